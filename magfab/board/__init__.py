"""The breakout board's parts: IPC-7351B footprints, placement, routing, rule checks, KiCad writing."""
