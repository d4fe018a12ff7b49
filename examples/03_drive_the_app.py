"""Example 3: drive the browser app from Python: start it, move a fiducial, read what every tab would show.

Run: .venv/bin/python examples/03_drive_the_app.py [--keep]   (--keep: leave the server running; open the URL)

`serve` starts the app on a free port and returns at once; the returned app has one controller per feature
(docs/architecture.md): `app.evaluate` moves points and changes settings, `app.views` the camera and the selection,
`app.plan` suggests fiducials, and the plug-in tabs' controllers (`app.tab(name, class)`) do what their tabs do: the
Diagnose tab's runs `rrbc diagnose` on the session's data. Each call updates every
open browser tab, exactly as the same action in the browser would; the numbers come from `app.session`.
"""

import sys
import time

import numpy as np

from rrbc_core.analysis.diagnosis_text import diagnosis_lines
from rrbc_viz.controllers.diagnose import DiagnoseController
from rrbc_viz.serve import serve

app = serve()  # the bundled work cell; serve("my_scene.toml") or serve("data.csv") for your own
try:
    print("the app is at", app.url)
    before = app.session.last.summary
    print(f"now: RMST rigid {before['rmst_rigid_mm']:.3f} mm, RRBC {before['rmst_rrbc_mm']:.3f} mm")

    # drag fiducial F1 200 mm along +x, as a drag in the browser would (start, updates, end)
    fid = app.session.last.fiducial_ids[0]
    start = np.array(app.session.last.fiducial_positions[0], float)
    app.evaluate.handle_drag("fiducials", fid, start, "start")
    for step in np.linspace(0.0, 200.0, 5)[1:]:
        ev = app.evaluate.handle_drag("fiducials", fid, start + [step, 0.0, 0.0], "update")
    ev = app.evaluate.handle_drag("fiducials", fid, start + [200.0, 0.0, 0.0], "end")
    if ev is None:  # the core refused the move (out of reach, inside a solid): the reason is the app's message
        print("refused:", app.last_message)
    else:
        after = ev.summary
        print(f"{fid} moved 200 mm: RMST rigid {after['rmst_rigid_mm']:.3f} mm, RRBC {after['rmst_rrbc_mm']:.3f} mm")

    app.views.select("targets", app.session.last.targets.ids[0])  # the info card and bullseye show this target
    app.evaluate.set_layer("heatmap", True)

    diagnosis = app.tab(
        "diagnose", DiagnoseController
    ).run()  # the Diagnose tab: the same lines `rrbc diagnose` prints for this data set
    if diagnosis is None:
        print("diagnose refused:", app.last_message)
    else:
        for line in diagnosis_lines(diagnosis)[:4]:
            print("  diagnose |", line)

    app.evaluate.handle_drag("fiducials", fid, start, "end")  # and back
    app.montecarlo.wait_idle(60.0)  # the Monte Carlo tab's run after the drag
    if "--keep" in sys.argv:
        print("serving; Ctrl+C to stop")
        while True:
            time.sleep(1.0)
finally:
    app.stop()
