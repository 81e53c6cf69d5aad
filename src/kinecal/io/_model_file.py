"""``model.yaml``: a calibrated model, self-contained and loadable again.

Every parameter is written with its value, unit, standard deviation and status, in the
file units of its kind (mm, deg, rad/m). The robot description and the model options are
embedded, so the file alone reproduces the predictions.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from kinecal import _yaml as yaml
from kinecal._version import __version__
from kinecal.errors import ConfigError
from kinecal.geometry import euler_zyx_to_matrix, matrix_to_euler_zyx
from kinecal.identification import CalibratedModel
from kinecal.io._files import atomic_write_text
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.robot import dump_robot, robot_from_dict

__all__ = ["FORMAT_VERSION", "load_model", "model_to_dict", "save_model"]

FORMAT_VERSION = 1


def _num(x: float) -> float | None:
    return None if not math.isfinite(float(x)) else float(x)


def _rwp_deg(R: np.ndarray) -> dict[str, float]:
    v = np.degrees(matrix_to_euler_zyx(R))
    return {"r": float(v[0]), "w": float(v[1]), "p": float(v[2])}


def model_to_dict(cal: CalibratedModel) -> dict[str, Any]:
    """The YAML document of a calibrated model."""
    m = cal.model
    s = m.spec
    spec: dict[str, Any] = {
        "name": s.name,
        "cam_rotation": s.cam_rotation,
        "hayati": list(s.hayati),
        "ntm_joints": list(s.ntm_joints),
        "ntm_order": s.ntm_order,
        "ntm_offset": s.ntm_offset,
        "load": s.load,
        "link": s.link,
        "link_bodies": list(s.link_bodies),
        "sets": list(s.sets),
        "markers": list(s.markers),
        "reference_payload_kg": cal.reference_payload_kg,
    }
    refs: dict[str, Any] = {}
    if not np.allclose(m.R_ref_base, np.eye(3)):
        refs["base"] = [_rwp_deg(R) for R in m.R_ref_base]
    if s.cam_rotation and not np.allclose(m.R_ref_cam, np.eye(3)):
        refs["cam"] = [_rwp_deg(R) for R in m.R_ref_cam]
    if refs:
        spec["reference_rotations_deg"] = refs
    params = {}
    to_file = m.layout.to_file
    for i, ps in enumerate(m.layout.specs):
        params[ps.name] = {
            "value": float(cal.params[i] * to_file[i]),
            "std": _num(cal.std[i] * to_file[i]),
            "unit": ps.unit.file_unit,
            "status": cal.status[i],
        }
    frames: dict[str, Any] = {}
    for which, labels in (("base", s.sets), ("cam", s.markers)):
        E = m.frame_euler(cal.params, which)
        for lab, e in zip(labels, E):
            key = which if lab == "" else f"{which}@{lab}"
            frames[key] = {
                **{k: float(v * 1e3) for k, v in zip("xyz", e[:3])},
                **{k: float(np.degrees(v)) for k, v in zip("rwp", e[3:])},
            }
    return {
        "kinecal_model": FORMAT_VERSION,
        "kinecal_version": __version__,
        "robot": dump_robot(m.robot),
        "model": spec,
        "parameters": params,
        "frames_mm_deg": frames,
        "info": cal.info,
    }


def save_model(path: str | Path, cal: CalibratedModel, *, force: bool = False) -> Path:
    """Write ``model.yaml`` atomically; refuse to overwrite unless ``force``."""
    doc = model_to_dict(cal)
    text = "# kinecal calibrated model: parameters in mm, deg, rad/m; std = 1 sigma\n"
    text += yaml.dump(_plain(doc), sort_keys=False, allow_unicode=True, width=100)
    return atomic_write_text(path, text, force=force)


def _plain(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    return x


def load_model(path: str | Path) -> CalibratedModel:
    """Read a ``model.yaml`` written by :func:`save_model`.

    Raises
    ------
    ConfigError
        Not a kinecal model file, unknown format version, parameters that do not match the
        model the file describes, or wrong units.
    """
    p = Path(path)
    try:
        doc = yaml.load(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{p}: model file not found.") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: not valid YAML ({exc}).".replace("\n", " ")) from None
    if not isinstance(doc, dict) or "kinecal_model" not in doc:
        raise ConfigError(f"{p}: not a kinecal model file (no 'kinecal_model' key).")
    if doc["kinecal_model"] != FORMAT_VERSION:
        raise ConfigError(
            f"{p}: model format {doc['kinecal_model']!r} is not supported."
        )
    for key in ("robot", "model", "parameters"):
        if key not in doc:
            raise ConfigError(f"{p}: missing key {key!r}.")
    robot = robot_from_dict(doc["robot"], source=f"{p}: robot")
    s = doc["model"]
    try:
        spec = ModelSpec(
            cam_rotation=bool(s["cam_rotation"]),
            hayati=tuple(s.get("hayati", [])),
            ntm_joints=tuple(s.get("ntm_joints", [])),
            ntm_order=int(s.get("ntm_order", 2)),
            ntm_offset=bool(s.get("ntm_offset", True)),
            load=bool(s.get("load", False)),
            link=str(s.get("link", "none")),
            link_bodies=tuple(s.get("link_bodies", [])),
            sets=tuple(str(x) for x in s.get("sets", [""])),
            markers=tuple(str(x) for x in s.get("markers", [""])),
            name=str(s.get("name", "custom")),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise ConfigError(f"{p}: model: {exc}") from None
    model = CalibrationModel(robot, spec)
    refs = s.get("reference_rotations_deg") or {}
    if refs:
        Rb = Rc = None
        if "base" in refs:
            Rb = np.stack(
                [
                    euler_zyx_to_matrix(np.radians([d["r"], d["w"], d["p"]]))
                    for d in refs["base"]
                ]
            )
        if "cam" in refs:
            Rc = np.stack(
                [
                    euler_zyx_to_matrix(np.radians([d["r"], d["w"], d["p"]]))
                    for d in refs["cam"]
                ]
            )
        model = model.with_references(Rb, Rc)
    params_doc = doc["parameters"]
    if not isinstance(params_doc, dict):
        raise ConfigError(f"{p}: parameters must be a mapping of name to value.")
    names = model.layout.names
    missing = [n for n in names if n not in params_doc]
    extra = [n for n in params_doc if n not in names]
    if missing or extra:
        what = (
            f"missing {missing[0]!r}" if missing else f"unknown parameter {extra[0]!r}"
        )
        raise ConfigError(
            f"{p}: parameters: {what} for the model described in the file."
        )
    values = np.zeros(model.size)
    std = np.full(model.size, np.nan)
    status = []
    to_file = model.layout.to_file
    for i, ps in enumerate(model.layout.specs):
        entry = params_doc[ps.name]
        if not isinstance(entry, dict) or "value" not in entry:
            raise ConfigError(
                f"{p}: parameters.{ps.name}: expected {{value, unit, std, status}}."
            )
        unit = entry.get("unit", ps.unit.file_unit)
        if unit != ps.unit.file_unit:
            raise ConfigError(
                f"{p}: parameters.{ps.name}.unit: expected {ps.unit.file_unit!r}; got {unit!r}."
            )
        try:
            values[i] = float(entry["value"]) / to_file[i]
            if entry.get("std") is not None:
                std[i] = float(entry["std"]) / to_file[i]
        except (TypeError, ValueError):
            raise ConfigError(
                f"{p}: parameters.{ps.name}: value must be a number."
            ) from None
        status.append(str(entry.get("status", "estimated")))
    try:
        return CalibratedModel(
            model,
            values,
            std,
            status,
            s.get("reference_payload_kg"),
            info=dict(doc.get("info") or {}),
        )
    except ValueError as exc:
        raise ConfigError(f"{p}: {exc}") from None
