"""The design pipeline: a design file to certified artefacts with their provenance.

The stages (`fahv.design.pipeline`), the tube forms they run
(`fahv.design.tube_forms`, the eight-state tube set of
`fahv.design.tube_set_design`) and the design's progress lines
(`fahv.design.stage_clock`).
"""
