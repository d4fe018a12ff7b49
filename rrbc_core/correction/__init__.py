"""RRBC itself: corrections at the fiducials and corrected targets (`rrbc`), error metrics (`metrics`: FRE, TRE,
RMST, expected TRE) and the whole `rrbc correct` run with its JSON (`pipeline`)."""
