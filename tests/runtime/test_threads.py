"""The thread-pool policy is in force where users run rrbc (issue 11; docs/threads.md).

Each check runs in a fresh Python process whose BLAS pools start as large as OpenBLAS allows on this machine
(OPENBLAS_NUM_THREADS=8, what a user might have in their shell), records the pool sizes with threadpoolctl
itself (not through rrbc's own report) from INSIDE the real code path — a CLI command, an app server callback,
a library call from a "notebook" — and prints them. Not timed.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

from rrbc_core.runtime import threads
from tests.paths import ROOT

DEMO = ROOT / "scenes" / "demo_workcell.toml"

RECORD = textwrap.dedent("""
    import json, sys
    from threadpoolctl import threadpool_info

    SEEN = []

    def pools():
        return sorted(int(i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas")

    def recording(module, name):
        original = getattr(module, name)

        def wrapper(*a, **k):
            SEEN.append(pools())
            return original(*a, **k)

        setattr(module, name, wrapper)

    import numpy, scipy.linalg  # both OpenBLAS copies loaded, as in any rrbc run
    BEFORE = pools()
""")


def _run(body: str) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    env["OPENBLAS_NUM_THREADS"] = "8"
    code = (
        RECORD
        + textwrap.dedent(body)
        + "\nprint('RESULT ' + json.dumps({'before': BEFORE, 'seen': SEEN, 'after': pools()}))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    line = [x for x in out.stdout.splitlines() if x.startswith("RESULT ")][-1]
    res = json.loads(line[len("RESULT ") :])
    if max(res["before"]) <= threads.THREADS:
        pytest.skip(f"OpenBLAS starts with {res['before']} threads here: nothing to limit on this machine")
    return res


def test_cli_command_runs_with_the_documented_pool_size():
    res = _run(f"""
        from rrbc_core.analysis import planning
        from rrbc_core import cli
        from rrbc_core.io import scene_toml
        recording(scene_toml, "load_scene")  # outside any library entry point: the process policy
        recording(planning, "predict_rmst")
        code = cli.main(["plan", {str(DEMO)!r}, "--add", "1", "--json"])
        assert code == 0
    """)
    assert len(res["seen"]) >= 2, "the plan command never reached load_scene and predict_rmst"
    assert all(p == [threads.THREADS] * len(p) for p in res["seen"]), res


def test_app_server_callbacks_run_with_the_documented_pool_size():
    res = _run("""
        import threading
        from rrbc_core.session import evaluation
        from rrbc_viz import tables
        from rrbc_viz.serve import serve
        recording(evaluation, "correct_points")
        recording(tables, "target_table")  # the app's own code, outside the library: the process policy
        app = serve(port=0)
        try:
            g = app.session.layout["fiducials"]
            p = g.positions[0] + [1.0, 0.0, 0.0]
            t = threading.Thread(target=app.evaluate.handle_drag, args=("fiducials", g.ids[0], p, "end"))
            t.start(); t.join()
        finally:
            app.stop()
    """)
    assert len(res["seen"]) >= 2, "the drag never reached correct_points and the table"
    assert all(p == [threads.THREADS] * len(p) for p in res["seen"]), res


def test_library_call_limits_pools_only_while_it_runs():
    """From a notebook: the call runs single-threaded and the user's pool sizes come back afterwards."""
    res = _run(f"""
        from rrbc_core.analysis import planning
        from rrbc_core.io.scene_toml import load_scene
        recording(planning, "_predict_fast")
        scene = load_scene({str(DEMO)!r})
        planning.predict_rmst(scene, scene.fiducials.positions)
    """)
    assert res["seen"] and all(p == [threads.THREADS] * len(p) for p in res["seen"]), res
    assert res["after"] == res["before"], res


def test_limited_is_reentrant_and_restores(monkeypatch):
    import numpy  # noqa: F401 - load both OpenBLAS copies, as any rrbc call does
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_info, threadpool_limits

    def blas():
        return sorted(int(i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas")

    monkeypatch.setattr(threads, "_process_policy", False)  # as in a user's process
    with threadpool_limits(2):
        start = blas()
        if max(start) <= threads.THREADS:
            pytest.skip("one core: nothing to limit")
        with threads.limited():
            with threads.limited():
                assert blas() == [threads.THREADS] * len(start)
            assert blas() == [threads.THREADS] * len(start)
        assert blas() == start
