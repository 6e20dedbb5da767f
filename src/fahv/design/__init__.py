"""The design pipeline: a design file to certified artefacts with their provenance.

The stages (:mod:`fahv.design.pipeline`), the tube forms they run
(:mod:`fahv.design.tube_forms`, the eight-state tube set of
:mod:`fahv.design.tube_set_design`) and the design's progress lines
(:mod:`fahv.design.stage_clock`).
"""
