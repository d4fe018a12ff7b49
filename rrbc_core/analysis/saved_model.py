"""An identified arm saved once and reused (`rrbc calibrate --save-model M.json`, then `--model M.json` on later
files; docs/calibration.md, "Calibrate once"). The file names the robot model it was identified on (the URDF as
given and the SHA-256 of its text, or a DH arm's name), the measured tip and base links, the tool point, the joint
columns, the geometric errors and load terms with their standard errors, and the gravity vector. Reused, the arm
stays as saved and only the sensor-to-robot transform of each station is fitted, to the registration and fiducial
rows (`calibration.fixed_transforms`): three registration points suffice. A model whose URDF, links, tool or joints differ from the file's is refused.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rrbc_core.analysis.calibration import Calibration
from rrbc_core.errors import InputError
from rrbc_core.models.chain import Chain
from rrbc_core.models.loads import named_terms

FORMAT = "rrbc-arm-model"
VERSION = 1
MAX_BYTES = 10_000_000  # a saved model is a few kB; a larger file is not one


@dataclass(frozen=True, eq=False)
class SavedModel:
    """A saved arm (module docstring). `urdf` the URDF as given (a path or a packaged name) or None for a DH arm
    `robot`; `urdf_sha256` its text's hash; `delta` (P,) and `delta_se` (P,) in `param_names` order (rad or mm, NaN:
    not identifiable alone); `terms`, `coef`, `coef_se` the load terms (rad/Nm or rad); `gravity` (3,) m/s²."""

    robot: str | None
    urdf: str | None
    urdf_sha256: str | None
    tip: str
    base: str
    tool_mm: tuple
    columns: tuple
    param_names: tuple
    delta: np.ndarray
    delta_se: np.ndarray
    terms: tuple
    coef: np.ndarray
    coef_se: np.ndarray
    gravity: tuple
    identified_on: str
    poses: int
    path: str = ""

    def describe(self) -> dict:
        """What `rrbc calibrate --model` reports about the model it used."""
        return {
            "path": self.path,
            "robot": self.robot,
            "urdf": self.urdf,
            "urdf_sha256": self.urdf_sha256,
            "tip": self.tip,
            "identified_on": self.identified_on,
            "poses": self.poses,
            "terms": list(self.terms),
        }

    def chain_for(self, urdf=None, tip=None, base=None, robot=None) -> tuple[Chain, Calibration]:
        """The saved arm's chain and its Calibration (identity transform: `fixed_transforms` fits them), after checking
        that the model asked for on the command line (`urdf`, `tip`, `base`, `robot`; None: the saved one) is the
        saved one."""
        from rrbc_core.analysis.robot_model import robot_chain

        where = self.path or "the saved model"
        if self.urdf is not None:
            if robot is not None:
                raise InputError(f"{where} was identified on the URDF {self.urdf}, not on --robot {robot}")
            from rrbc_core.models.urdf import resolve_urdf

            path = resolve_urdf(urdf if urdf is not None else self.urdf)
            digest = urdf_digest(path)
            if digest != self.urdf_sha256:
                raise InputError(
                    f"{where} was identified on a URDF with SHA-256 {str(self.urdf_sha256)[:12]}… ({self.urdf}); "
                    f"{path} is another ({digest[:12]}…): the saved errors do not apply to it"
                )
            chain = robot_chain(None, path, tip or self.tip, base or self.base)
        else:
            if urdf is not None or (robot is not None and robot != self.robot):
                raise InputError(f"{where} was identified on --robot {self.robot}, not on {urdf or robot}")
            chain = robot_chain(self.robot, None, None, None)
        chain = chain.with_tool(self.tool_mm)
        if chain.tip != self.tip or chain.base != self.base:
            raise InputError(
                f"{where} is the chain {self.base} → {self.tip}; asked for {chain.base} → {chain.tip} (--tip, --base)"
            )
        if chain.columns != self.columns or chain.param_names != self.param_names:
            raise InputError(f"{where}: its joints ({', '.join(self.columns)}) are not this model's")
        cal = Calibration(
            chain=chain,
            delta=self.delta,
            delta_se=self.delta_se,
            identifiable=np.isfinite(self.delta_se),
            rotation=np.eye(3),
            translation=np.zeros(3),
            rank=0,
            combinations=(),
            sigma_mm=float("nan"),
            residuals=np.zeros((0, 3)),
            terms=named_terms(chain, self.terms),
            coef=self.coef,
            coef_se=self.coef_se,
            coef_identifiable=np.isfinite(self.coef_se),
            gravity=self.gravity,
        )
        return chain, cal


def urdf_digest(path) -> str:
    """SHA-256 (hex) of a URDF file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def from_calibration(cal: Calibration, robot: str | None, urdf, identified_on: str, poses: int) -> SavedModel:
    """The SavedModel of an identified arm; `robot` the DH arm's name or `urdf` the URDF as given."""
    chain = cal.chain
    ref = None
    if urdf is not None:
        ref = str(urdf) if not Path(str(urdf)).exists() else str(Path(str(urdf)).resolve())
    return SavedModel(
        robot=None if urdf is not None else robot,
        urdf=ref,
        urdf_sha256=None if urdf is None else urdf_digest(chain.source),
        tip=chain.tip,
        base=chain.base,
        tool_mm=tuple(float(v) for v in chain.tool),
        columns=chain.columns,
        param_names=chain.param_names,
        delta=np.asarray(cal.delta, float),
        delta_se=np.asarray(cal.delta_se, float),
        terms=tuple(t.name for t in cal.terms),
        coef=np.asarray(cal.coef, float),
        coef_se=np.asarray(cal.coef_se, float),
        gravity=tuple(cal.gravity),
        identified_on=identified_on,
        poses=int(poses),
    )


def _num(v) -> float | None:
    return None if not np.isfinite(v) else float(v)


def to_json(m: SavedModel) -> dict:
    """The saved model's JSON object (docs/formats/arm-model.md)."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "robot": m.robot,
        "urdf": m.urdf,
        "urdf_sha256": m.urdf_sha256,
        "tip": m.tip,
        "base": m.base,
        "tool_mm": list(m.tool_mm),
        "joints": list(m.columns),
        "gravity_m_s2": list(m.gravity),
        "identified_on": m.identified_on,
        "poses": m.poses,
        "parameters": [
            {"name": n, "error": float(d), "std_error": _num(se)}
            for n, d, se in zip(m.param_names, m.delta, m.delta_se)
        ],
        "load_terms": [
            {"name": n, "value": float(c), "std_error": _num(se)} for n, c, se in zip(m.terms, m.coef, m.coef_se)
        ],
    }


def save_model(path, m: SavedModel) -> None:
    """Write the model (atomically: never a partial file)."""
    from rrbc_core.io.measurements_write import atomic_write_text

    p = Path(path)
    if p.is_dir() or not p.parent.is_dir():
        raise InputError(f"--save-model {p}: must be a file in an existing directory")
    atomic_write_text(p, json.dumps(to_json(m), indent=1) + "\n")


def load_model(path) -> SavedModel:
    """Read a saved model; InputError naming what is wrong with the file."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"--model {p}: no such file")
    if p.stat().st_size > MAX_BYTES:
        raise InputError(f"--model {p}: {p.stat().st_size} bytes is not a saved arm model")
    try:
        d = json.loads(p.read_text(encoding="utf-8"))
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise ValueError(f"not an {FORMAT} file (written by rrbc calibrate --save-model)")
        if d.get("version") != VERSION:
            raise ValueError(f"version {d.get('version')!r}; this rrbc reads version {VERSION}")
        params, loads = d["parameters"], d["load_terms"]
        m = SavedModel(
            robot=d["robot"],
            urdf=d["urdf"],
            urdf_sha256=d["urdf_sha256"],
            tip=str(d["tip"]),
            base=str(d["base"]),
            tool_mm=tuple(float(v) for v in d["tool_mm"]),
            columns=tuple(str(c) for c in d["joints"]),
            param_names=tuple(str(x["name"]) for x in params),
            delta=np.array([float(x["error"]) for x in params]),
            delta_se=np.array([np.nan if x["std_error"] is None else float(x["std_error"]) for x in params]),
            terms=tuple(str(x["name"]) for x in loads),
            coef=np.array([float(x["value"]) for x in loads]),
            coef_se=np.array([np.nan if x["std_error"] is None else float(x["std_error"]) for x in loads]),
            gravity=tuple(float(v) for v in d["gravity_m_s2"]),
            identified_on=str(d.get("identified_on", "")),
            poses=int(d.get("poses", 0)),
            path=str(p),
        )
    except (ValueError, KeyError, TypeError) as exc:
        raise InputError(f"--model {p}: {exc}") from None
    if (m.urdf is None) == (m.robot is None) or len(m.tool_mm) != 3 or len(m.gravity) != 3:
        raise InputError(f"--model {p}: it must name a URDF or a DH robot, a tool point (3) and gravity (3)")
    if not (np.all(np.isfinite(m.delta)) and np.all(np.isfinite(m.coef))):
        raise InputError(f"--model {p}: its errors must be finite numbers")
    return m


__all__ = ["SavedModel", "from_calibration", "load_model", "save_model", "to_json", "urdf_digest"]


def export_calibrated_urdf(path: str, urdf, cal: Calibration, source: str, poses: int) -> None:
    """`rrbc calibrate --export-urdf`: write the identified arm `cal` as a URDF (`models.urdf_export`) to `path`, atomically."""
    from rrbc_core.io.measurements_write import atomic_write_text
    from rrbc_core.models.urdf import resolve_urdf
    from rrbc_core.models.urdf_export import calibrated_urdf

    notes = [
        f"Calibrated by rrbc calibrate from {source} ({poses} poses; {cal.rank} parameter combinations identified,",
        f"residual noise {cal.sigma_mm:.4g} mm per axis): joint origins and offsets of {resolve_urdf(urdf).name}",
        "updated; link rrbc_tool is the measured tool point. The sensor-to-robot transform is not part of the arm.",
    ]
    if cal.terms:
        notes.append("Load terms (no URDF element; apply them as rrbc's models.loads does):")
        notes += [
            f"  {t.name} = {c:.6g} {t.unit} (standard error {se:.2g})"
            for t, c, se in zip(cal.terms, cal.coef, cal.coef_se)
        ]
    atomic_write_text(path, calibrated_urdf(resolve_urdf(urdf), cal.chain, cal.delta, notes))
