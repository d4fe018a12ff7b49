"""Holding the simulation against published measurements: Van Wyk & Marvel (2018) — the tables
(`reference_data`), the experiment simulated (`reproduction`), model fitting (`model_fit`), the analysis and its
report (`vanwyk2018`, `vanwyk2018_report`)."""
