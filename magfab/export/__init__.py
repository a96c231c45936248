"""Renderers from values to bytes (CAD, KiCad, firmware, readout, checklist, BOM, figures, report) and the toolchain
drivers."""
