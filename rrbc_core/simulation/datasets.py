"""One simulated data set of a cell in the measurement-file format: what `rrbc simulate --out` writes and what the
app's session holds for a scene (`session.data_set`). Each point's noise comes from its own generator seeded by
(seed, id) (`models.measurement.MeasurementModel.read_each`), so the same point reads the same in both."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.models.measurement import MeasurementModel
from rrbc_core.simulation.montecarlo import Measured, WorkCell, work_cell_from_scene

if TYPE_CHECKING:
    from rrbc_core.io.scene import Scene

__all__ = ["joint_columns", "measured_data", "measurement_set", "simulated_data"]


def measurement_set(cell: WorkCell, measured: Measured, trial: int = 0) -> MeasurementSet:
    """One simulated session in the measurement-file format: check rows carry the truth, target rows no robot
    values; an extra `target` column names the target a check point belongs to."""
    robot = measured.robot[trial].copy()
    roles = np.array(cell.roles)
    robot[roles == "check"] = measured.truth[roles == "check"]
    robot[roles == "target"] = np.nan
    return MeasurementSet(
        ids=cell.ids,
        roles=cell.roles,
        sensor=measured.sensor[trial],
        robot=robot,
        time=cell.time,
        lines=tuple(0 for _ in cell.ids),
        source=f"<simulated {cell.name}>",
        extra={"target": tuple(cell.check_target), **joint_columns(cell)},
    )


def joint_columns(cell: WorkCell) -> dict:
    """The columns q1..q6 (degrees, as text) of a cell whose robot error model has an arm term (kinematic, else
    compliance): the joints the controller reads where the (true) arm reaches each point — what the robot measured a
    registration or fiducial row at, and the configuration it will use for a check or target row — and the tool
    point in the flange's frame, mm (`tool_x`, `tool_y`, `tool_z`: `io.joints.file_tool`), so that `rrbc diagnose`,
    `rrbc calibrate` and `rrbc check-model` read the file as it is. {} without an arm term. With both terms the
    kinematic term's joints are written (the compliance term solves its own)."""
    from rrbc_core.models.armterms import ArmErrors
    from rrbc_core.models.errorterms import Compliance, Kinematic

    chained = [t for t in cell.error_model.robot if isinstance(t, ArmErrors)]
    if chained:  # the arm's own columns (a URDF's joint names in ROS units, or q1..q6 in degrees) and its tool
        term = chained[0]
        chain = term.chain
        qa = term.joints(cell.point_set())
        cols = {inp.column: tuple(repr(float(v)) for v in qa[:, i] / inp.scale) for i, inp in enumerate(chain.inputs)}
        tool_cols = zip(("tool_x", "tool_y", "tool_z"), chain.tool)
        cols.update({c: tuple(f"{float(v):g}" for _ in range(len(qa))) for c, v in tool_cols})
        return cols
    arm: list[Kinematic | Compliance] = [t for t in cell.error_model.robot if isinstance(t, Kinematic)]
    arm += [t for t in cell.error_model.robot if isinstance(t, Compliance)]
    if not arm:
        return {}
    q = np.degrees(arm[0].joints(cell.point_set()))
    out = {f"q{j + 1}": tuple(f"{v:.6f}" for v in q[:, j]) for j in range(6)}
    tool = (0.0, 0.0, float(arm[0].dh.tool_mm))
    out.update({c: tuple(f"{v:g}" for _ in range(len(q))) for c, v in zip(("tool_x", "tool_y", "tool_z"), tool)})
    return out


def simulated_data(scene: Scene, *, seed: int = 0, layout: str | None = None) -> MeasurementSet:
    """One simulated measurement of a scene, as a measurement file holds it: what `rrbc simulate --out` writes.

    Parameters
    ----------
    scene : Scene
        A loaded scene.
    seed : int
        The same seed as `simulate` uses for the same cell (check points); each point's noise is drawn from its
        own generator seeded by (seed, id) (`measurement.point_seed`), as the app draws it.
    layout : str, optional
        A named layout of the scene.

    Returns
    -------
    MeasurementSet
        Registration, fiducial, target and check rows with their times (and joint columns with a kinematic arm);
        check rows carry the robot-frame truth (the command that reaches the point).
    """
    if layout:
        scene = scene.with_layout(layout)
    return measured_data(work_cell_from_scene(scene, seed=seed), seed)


def measured_data(cell: WorkCell, seed: int, bias_scale: float = 1.0, noise_scale: float = 1.0) -> MeasurementSet:
    """One measured data set of a cell (module `measurement`: `MeasurementModel.read_each`, each point's noise
    seeded by (seed, id)) in the measurement-file format (`measurement_set`). The one place a simulated data set
    is made: `rrbc simulate --out` and the app's data (its Diagnose tab and CSV download) both come from here.

    Parameters
    ----------
    cell : WorkCell
        The points, their roles, times and tool orientations, and the error model.
    seed : int
        The data set's seed.
    bias_scale, noise_scale : float
        Sizes of the error model's deterministic and random terms (1: as given).

    Returns
    -------
    MeasurementSet
        As `measurement_set`.
    """
    model = MeasurementModel(cell.sensor_to_robot, cell.error_model, cell.joint_seed, bias_scale, noise_scale)
    r = model.read_each(cell.point_set(), cell.ids, seed)
    return measurement_set(cell, Measured(r.sensor, r.robot, r.truth))
