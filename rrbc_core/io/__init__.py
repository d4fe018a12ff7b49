"""Files: measurement files (`measurements`: read, validate, write) and scenes (`scene`: the TOML work-cell format,
validated, and the Scene model)."""
