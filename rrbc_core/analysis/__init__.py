"""Analyses of a cell or its data: hidden effects in measured data (`diagnosis`, `rrbc diagnose`) and fiducial
planning (`planning`, `rrbc plan`)."""
