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

from kinecal._version import __version__
from kinecal.errors import ConfigError
from kinecal.geometry import euler_zyx_to_matrix, matrix_to_euler_zyx
from kinecal.io._files import atomic_write_text
from kinecal.io._model_bounds import (
    check_frames,
    check_info,
    check_payload,
    check_result,
    check_value,
    document_fingerprint,
    robot_fingerprint,
)
from kinecal.io._model_checks import check_std, check_text, stamp_as_written
from kinecal.io._model_paths import source_as_read, source_as_written
from kinecal.io._parameters import parameter_records
from kinecal.io._yaml_plain import dump as dump_plain
from kinecal.measurement import CalibratedModel
from kinecal.measurement._calibrated import STATUSES
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.robot import dump_robot, robot_from_dict
from kinecal.robot._param_names import canonical_parameter_name

__all__ = ["FORMAT_VERSION", "load_model", "model_to_dict", "save_model"]

FORMAT_VERSION = 1


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
    params = {
        r["name"]: {
            k: r[k] for k in ("value", "std", "unit", "status", "joint_name") if k in r
        }
        for r in parameter_records(cal)
    }
    robot = dump_robot(m.robot)
    return {
        "kinecal_model": FORMAT_VERSION,
        "kinecal_version": __version__,
        "robot": robot,
        "robot_sha256": document_fingerprint(robot),  # robot_fingerprint(m.robot)
        "model": spec,
        "parameters": params,
        "frames_mm_deg": _frames(cal),
        "info": cal.info,
    }


def _frames(cal: CalibratedModel) -> dict[str, Any]:
    """The user and cam frames in mm and deg (``frames_mm_deg``: derived from the
    parameters, for the reader; checked against them when the file is loaded)."""
    m, s = cal.model, cal.model.spec
    frames: dict[str, Any] = {}
    for which, labels in (("base", s.sets), ("cam", s.markers)):
        E = m.frame_euler(cal.params, which)
        for lab, e in zip(labels, E):
            key = which if lab == "" else f"{which}@{lab}"
            frames[key] = {
                **{k: float(v * 1e3) for k, v in zip("xyz", e[:3])},
                **{k: float(np.degrees(v)) for k, v in zip("rwp", e[3:])},
            }
    return frames


def save_model(path: str | Path, cal: CalibratedModel, *, force: bool = False) -> Path:
    """Write ``model.yaml`` atomically; refuse to overwrite unless ``force``, and a
    model :func:`load_model` would refuse (a DataError naming its data)."""
    return save_model_as_read(path, cal, force=force, read=False)[0]


def save_model_as_read(
    path: str | Path, cal: CalibratedModel, *, force: bool = False, read: bool = True
) -> tuple[Path, CalibratedModel | None]:
    """:func:`save_model`, and (``read``) what :func:`load_model` of the file returns,
    built from the document (not read and parsed again) where its text was written
    without PyYAML (a document that reads back as itself); None otherwise."""
    check_result(cal, str(cal.info.get("source") or path))
    doc = _plain(model_to_dict(cal))
    if isinstance(doc.get("info"), dict) and "source" in doc["info"]:
        doc["info"]["source"] = source_as_written(doc["info"]["source"], path)
    text = "# kinecal calibrated model: parameters in mm, deg, rad/m; std = 1 sigma\n"
    body = dump_plain(doc)
    if body is None:
        from kinecal import _yaml as yaml

        text += yaml.dump(doc, sort_keys=False, allow_unicode=True, width=100)
        return atomic_write_text(path, text, force=force), None
    p = atomic_write_text(path, text + body, force=force)
    if not read:
        return p, None
    from kinecal._outputs import note_input

    note_input(p)
    return p, _model_from_doc(_checked_doc(doc, p), p)


def _plain(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    return x


# Model names kinecal writes: the presets, the candidates of --model auto (also as
# "auto:<candidate>"), a simulated truth and a hand-built spec.
_CANDIDATES = ("kinematic", "ntm", "rfcm", "full", "load", "load+link")
_NAMES = (*_CANDIDATES, "custom", "truth")
_MAX_LABEL = 80
_SPEC_KEYS = {
    "name",
    "cam_rotation",
    "hayati",
    "ntm_joints",
    "ntm_order",
    "ntm_offset",
    "load",
    "link",
    "link_bodies",
    "sets",
    "markers",
    "reference_payload_kg",
    "reference_rotations_deg",
}
_TOP_KEYS = {
    "kinecal_model",
    "kinecal_version",
    "robot",
    "robot_sha256",
    "model",
    "parameters",
    "frames_mm_deg",
    "info",
}


def _model_name_ok(name: Any) -> bool:
    """A model's name is a label (the terms are the other keys of the section): one of
    :data:`_NAMES`, or ``auto:`` and the label of the candidate ``--model auto`` chose
    (any one-line printable text: the candidates' labels depend on the robot)."""
    if not isinstance(name, str):
        return False
    if name in _NAMES:
        return True
    label = name[5:] if name.startswith("auto:") else ""
    return (
        0 < len(label) <= _MAX_LABEL and label.isprintable() and label.strip() == label
    )


def _bool(s: dict[str, Any], key: str, default: bool | None, where: str) -> bool:
    v = s.get(key, default)
    if key not in s and default is None:  # (was: 'got None')
        raise ConfigError(f"{where}: missing key {key!r} (true or false).")
    if not isinstance(v, bool):
        raise ConfigError(f"{where}.{key}: expected true or false; got {v!r}.")
    return v


def _joints(s: dict[str, Any], key: str, n: int, where: str) -> tuple[int, ...]:
    v = s.get(key, [])
    if v is None:
        v = []
    if not isinstance(v, list) or not all(
        isinstance(j, int) and not isinstance(j, bool) and 1 <= j <= n for j in v
    ):
        raise ConfigError(
            f"{where}.{key}: expected a list of joint numbers 1..{n}; got {v!r}."
        )
    return tuple(v)


def _labels(s: dict[str, Any], key: str, where: str) -> tuple[str, ...]:
    v = s.get(key, [""])
    if not isinstance(v, list) or not v or not all(isinstance(x, str) for x in v):
        raise ConfigError(f"{where}.{key}: expected a list of labels; got {v!r}.")
    if len(set(v)) != len(v):
        raise ConfigError(f"{where}.{key}: expected unique labels; got {v!r}.")
    return tuple(v)


def _spec(s: Any, n_joints: int, where: str) -> ModelSpec:
    """The model section of a model file, validated."""
    if not isinstance(s, dict):
        raise ConfigError(f"{where}: expected a mapping; got {type(s).__name__}.")
    unknown = sorted(set(map(str, s)) - _SPEC_KEYS)
    if unknown:
        raise ConfigError(
            f"{where}: unknown key {unknown[0]!r} (allowed: {', '.join(sorted(_SPEC_KEYS))})."
        )
    name = s.get("name", "custom")
    if not _model_name_ok(name):
        raise ConfigError(
            f"{where}.name: unknown model {name!r}; expected one of {', '.join(_NAMES)} "
            "(or auto:<candidate label>)."
        )
    order = s.get("ntm_order", 2)
    if not isinstance(order, int) or isinstance(order, bool) or not 1 <= order <= 8:
        raise ConfigError(f"{where}.ntm_order: expected 1..8; got {order!r}.")
    link = s.get("link", "none")
    if not isinstance(link, str):
        raise ConfigError(f"{where}.link: expected a name; got {link!r}.")
    try:
        return ModelSpec(
            cam_rotation=_bool(s, "cam_rotation", None, where),
            hayati=_joints(s, "hayati", n_joints, where),
            ntm_joints=_joints(s, "ntm_joints", n_joints, where),
            ntm_order=order,
            ntm_offset=_bool(s, "ntm_offset", True, where),
            load=_bool(s, "load", False, where),
            link=link,
            link_bodies=_joints(s, "link_bodies", n_joints, where),
            sets=_labels(s, "sets", where),
            markers=_labels(s, "markers", where),
            name=name,
        )
    except ConfigError:  # a field's own message names the file and the key already
        raise
    except ValueError as exc:  # ModelError: an inconsistent combination
        raise ConfigError(f"{where}: {str(exc).rstrip('.')}{_absent(s)}.") from None


def _absent(s: dict[str, Any]) -> str:
    """The terms a model section lacks (they take their defaults), for the message of a
    file of another layout (a hand edit, another version) that then fails."""
    optional = {"name", "reference_payload_kg", "reference_rotations_deg"}
    absent = sorted(_SPEC_KEYS - set(map(str, s)) - optional)
    return (
        f" (the model section has no {', '.join(absent)}: defaults taken)"
        if absent
        else ""
    )


def _rotations(refs: Any, key: str, count: int, where: str) -> np.ndarray | None:
    if key not in refs:
        return None
    rows = refs[key]
    w = f"{where}.{key}"
    if not isinstance(rows, list) or len(rows) != count:
        raise ConfigError(f"{w}: expected a list of {count} {{r, w, p}} rotations.")
    out = []
    for i, d in enumerate(rows):
        if not isinstance(d, dict) or set(d) != {"r", "w", "p"}:
            raise ConfigError(f"{w}[{i}]: expected {{r, w, p}} in deg; got {d!r}.")
        v = [_finite(d[k], f"{w}[{i}].{k}") for k in "rwp"]
        out.append(euler_zyx_to_matrix(np.radians(v)))
    return np.stack(out)


def _finite(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ConfigError(f"{where}: expected a finite number; got {v!r}.")
    return float(v)


def _read_doc(p: Path) -> dict[str, Any]:
    from kinecal.robot._robot_file import read_text_file

    try:
        text = read_text_file(p, "a model.yaml")
    except FileNotFoundError:
        raise ConfigError(f"{p}: model file not found.") from None
    except IsADirectoryError:
        raise ConfigError(
            f"{p}: is a folder; expected a model.yaml (e.g. {p / 'model.yaml'})."
        ) from None
    from kinecal import _yaml as yaml

    try:
        doc = yaml.load(text)  # hand-typed numbers: 1e-3 as YAML 1.2 reads it
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: not valid YAML ({exc}).".replace("\n", " ")) from None
    return _checked_doc(stamp_as_written(doc, text), p)


def _kind_of(doc: Any) -> str:
    """What a document handed as a model is instead (a robot file, a URDF, a CSV, a
    report), as '; it is ...' (empty when unknown)."""
    if isinstance(doc, dict) and {"joints", "convention"} <= set(doc):
        what = "a robot file: calibrate with it (--robot) to get a model.yaml"
    elif isinstance(doc, str) and doc.lstrip().startswith("<"):
        what = "an XML document (a URDF?): a robot, not a calibrated model (--robot)"
    elif isinstance(doc, str) and "," in doc.split("\n", 1)[0]:
        what = "a CSV table: data, not a calibrated model"
    elif isinstance(doc, dict) and {"kinecal_version", "data"} <= set(doc):
        what = "a calibration's report.json: its model.yaml is beside it"
    else:
        return ""
    return f"; it is {what}"


def _checked_doc(doc: Any, p: Path) -> dict[str, Any]:
    if not isinstance(doc, dict) or "kinecal_model" not in doc:
        raise ConfigError(
            f"{p}: not a kinecal model file (no 'kinecal_model' key){_kind_of(doc)}."
        )
    if type(doc["kinecal_model"]) is not int or doc["kinecal_model"] != FORMAT_VERSION:
        raise ConfigError(
            f"{p}: model format {doc['kinecal_model']!r} is not supported; expected "
            f"{FORMAT_VERSION}."
        )
    unknown = sorted(set(map(str, doc)) - _TOP_KEYS)
    if unknown:
        raise ConfigError(
            f"{p}: unknown key {unknown[0]!r} (allowed: {', '.join(sorted(_TOP_KEYS))})."
        )
    for key in ("robot", "model", "parameters"):
        if key not in doc:
            raise ConfigError(f"{p}: missing key {key!r}.")
    if not isinstance(doc.get("info") or {}, dict):
        raise ConfigError(f"{p}: info: expected a mapping; got {doc['info']!r}.")
    check_text(doc, "kinecal_version", f"{p}: kinecal_version", 100)
    return doc


def load_model(path: str | Path) -> CalibratedModel:
    """Read a ``model.yaml`` written by :func:`save_model` (or edited by hand).

    Everything is validated: unknown keys, the model's options and name, every
    parameter's value (finite), unit (the one of its kind), std (null or >= 0) and
    status, the reference payload (> 0).

    Raises
    ------
    ConfigError
        With a one-line message naming the file and the key.
    """
    from kinecal._outputs import note_input

    note_input(path)
    p = Path(path)
    return _model_from_doc(_read_doc(p), p)


def _model_from_doc(doc: dict[str, Any], p: Path) -> CalibratedModel:
    robot = robot_from_dict(doc["robot"], source=f"{p}: robot")
    stamp = doc.get("robot_sha256")
    if (  # (the robot rebuilt and dumped again only when the text's does not match)
        stamp is not None
        and stamp != document_fingerprint(doc["robot"])
        and stamp != robot_fingerprint(robot)
    ):
        raise ConfigError(
            f"{p}: robot_sha256: {stamp!r}, but the robot section's fingerprint is "
            f"{robot_fingerprint(robot)!r}: the robot was edited after the calibration "
            "(its parameters belong to the robot it was calibrated with); expected the "
            "robot section as kinecal wrote it."
        )
    s = doc["model"]
    spec = _spec(s, robot.n_joints, f"{p}: model")
    payload = s.get("reference_payload_kg")
    if payload is not None:
        where = f"{p}: model.reference_payload_kg"
        check_payload(_finite(payload, where), robot, where)
    why = _absent(s)
    try:
        model = CalibrationModel(robot, spec)
    except ValueError as exc:
        raise ConfigError(f"{p}: model: {str(exc).rstrip('.')}{why}.") from None
    refs = s.get("reference_rotations_deg") or {}
    if not isinstance(refs, dict) or not set(refs) <= {"base", "cam"}:
        raise ConfigError(
            f"{p}: model.reference_rotations_deg: expected {{base: [...], cam: [...]}}."
        )
    if refs:
        where = f"{p}: model.reference_rotations_deg"
        Rb = _rotations(refs, "base", len(spec.sets), where)
        Rc = _rotations(refs, "cam", len(spec.markers), where)
        model = model.with_references(Rb, Rc)
    check_info(doc.get("info"), robot, spec.cam_rotation, p)
    check_text(doc.get("info") or {}, "source", f"{p}: info.source", 4096)
    values, std, status = _parameters(doc["parameters"], model, p, why)
    cal = CalibratedModel(
        model,
        values,
        std,
        status,
        None if payload is None else float(payload),
        info=dict(doc.get("info") or {}),
    )
    if "source" in cal.info:  # relative to the model file's folder (_model_paths)
        cal.info["source"] = source_as_read(cal.info["source"], p)
    check_frames(doc.get("frames_mm_deg"), _frames(cal), p)
    return cal


def _parameters(
    params_doc: Any, model: CalibrationModel, p: Path, why: str = ""
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Values, std (SI) and status of every parameter, validated."""
    if not isinstance(params_doc, dict):
        raise ConfigError(f"{p}: parameters must be a mapping of name to value.")
    names = model.layout.names
    canon: dict[str, Any] = {}
    for k, v in params_doc.items():
        c = canonical_parameter_name(str(k), model.robot.joint_names)
        if c in canon:
            raise ConfigError(f"{p}: parameters: {k!r} and {c!r} name one parameter.")
        canon[c] = v
    params_doc = canon
    missing = [n for n in names if n not in params_doc]
    extra = [n for n in params_doc if n not in names]
    if missing or extra:
        what = (
            f"missing {missing[0]!r}" if missing else f"unknown parameter {extra[0]!r}"
        )
        raise ConfigError(
            f"{p}: parameters: {what} for the model described in the file{why}."
        )
    values = np.zeros(model.size)
    std = np.full(model.size, np.nan)
    status = []
    to_file = model.layout.to_file
    for i, ps in enumerate(model.layout.specs):
        where = f"{p}: parameters.{ps.name}"
        entry = params_doc[ps.name]
        if not isinstance(entry, dict) or "value" not in entry:
            raise ConfigError(f"{where}: expected {{value, unit, std, status}}.")
        bad = sorted(
            set(map(str, entry)) - {"value", "unit", "std", "status", "joint_name"}
        )
        if bad:
            raise ConfigError(
                f"{where}: unknown key {bad[0]!r} (allowed: joint_name, std, status, "
                "unit, value)."
            )
        jn = entry.get("joint_name")
        if jn is not None and (
            ps.joint is None or jn != model.robot.joint_names[ps.joint - 1]
        ):
            want = "none" if ps.joint is None else model.robot.joint_names[ps.joint - 1]
            raise ConfigError(
                f"{where}.joint_name: expected {want!r} (the robot's name of joint "
                f"{ps.joint}); got {jn!r}."
            )
        unit = entry.get("unit", ps.unit.file_unit)
        if unit != ps.unit.file_unit:
            raise ConfigError(
                f"{where}.unit: expected {ps.unit.file_unit!r}; got {unit!r}."
            )
        v = _finite(entry["value"], f"{where}.value")
        check_value(model, i, v, f"{where}.value")
        values[i] = v / to_file[i]
        st = entry.get("status", "estimated")
        if st not in STATUSES:
            raise ConfigError(
                f"{where}.status: expected one of {', '.join(STATUSES)}; got {st!r}."
            )
        if entry.get("std") is not None:
            sd = _finite(entry["std"], f"{where}.std")
            check_std(model, i, sd, st, f"{where}.std")
            std[i] = sd / abs(to_file[i])
        status.append(st)
    return values, std, status
