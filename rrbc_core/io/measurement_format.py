"""The measurement file's format as constants (spec: docs/formats/measurement-file.md): its roles, columns, the
plain decimal a number cell holds and the limits on values and size. Read by `io.measurements` (the row-by-row
reader and the set) and `io.measurements_columnar` (the columnar reader)."""

from __future__ import annotations

ROLES = ("registration", "fiducial", "both", "target", "check")
REGISTRATION_ROLES = ("registration", "both")
FIDUCIAL_ROLES = ("fiducial", "both")
ROBOT_REQUIRED_ROLES = ("registration", "fiducial", "both", "check")

SENSOR_COLUMNS = ("sensor_x", "sensor_y", "sensor_z")
ROBOT_COLUMNS = ("robot_x", "robot_y", "robot_z")
REQUIRED_COLUMNS = ("id", "role") + SENSOR_COLUMNS + ROBOT_COLUMNS
STANDARD_COLUMNS = REQUIRED_COLUMNS + ("time",)
#: the optional column naming each row's station (io.groups): rows with one value are registered and corrected apart
GROUP_COLUMN = "group"

# A plain decimal number (what `repr(float)` and spreadsheets write); stricter than float(), which would also
# take '1_000', 'nan', 'infinity' and non-ASCII digits.
NUMBER_PATTERN = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
COORDINATE_LIMIT_MM = 1e9  # |coordinate| at most this (a km-scale cell is 1e6 mm): larger is a unit or format slip
FILE_LIMIT_BYTES = 512 * 2**20  # a measurement file is read only up to this size (about 5 million rows)
TIME_LIMIT_S = 1e12  # |time| at most this (30 000 years of seconds; Unix times are ~1.7e9)
#: files at least this long are read by columns (`io.measurements_columnar`); below it pyarrow's import, about
#: 0.1 s, costs more than it saves (fresh processes on this machine: 10 000 rows, 1.3 MB, 0.25 s either way;
#: 20 000 rows 0.26 s by columns, 0.32 s row by row; `benchmarks/run.py big_inputs` measures 10 000)
COLUMNAR_MIN_CHARS = 2 << 20
