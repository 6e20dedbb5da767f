"""Plant and fault-injector nodes of the SIL graph (adapters of fahv.loop.cores)."""
