"""Model JSON files (docs/design.md section 6): read and validated at the boundary, written atomically."""
from __future__ import annotations

import datetime as _dt
import hashlib
import json
import math
import os
from pathlib import Path
from typing import Iterable

from ..core.model import Model
from ..core.params import Calibration, EffectSpec, Geometry, KnobIdentification, KnobModel, PARAM_NAMES
from ..errors import ModelError
from ..estimate import Estimate
from .files import atomic_write_text
from .runs import MODEL_FORMAT, MODEL_VERSION


def _num(value: object, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ModelError(f"{what} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ModelError(f"{what} must be finite, got {value!r}")
    return v


def model_from_dict(data: object, source: str = "<model>") -> Model:
    """Build a :class:`Model` from the parsed JSON of a model file, validating everything."""
    if not isinstance(data, dict):
        raise ModelError(f"{source}: not a hyst model (the top level must be a JSON object)")
    if data.get("format") != MODEL_FORMAT:
        raise ModelError(f"{source}: not a hyst model (\"format\" must be {MODEL_FORMAT!r}, "
                         f"got {data.get('format')!r})")
    version = data.get("version")
    if version != MODEL_VERSION:
        raise ModelError(f"{source}: unknown model version {version!r} (this hyst reads version {MODEL_VERSION})")
    knobs_raw = data.get("knobs")
    if not isinstance(knobs_raw, dict) or not knobs_raw:
        raise ModelError(f"{source}: \"knobs\" must be an object with knob \"1\" and/or \"2\"")
    knobs: dict[int, KnobModel] = {}
    for key, params in knobs_raw.items():
        if key not in ("1", "2"):
            raise ModelError(f"{source}: unknown knob {key!r} (knobs are \"1\" and \"2\")")
        if not isinstance(params, dict):
            raise ModelError(f"{source}: knob {key} must be an object of parameters")
        missing = [p for p in PARAM_NAMES if p != "offset" and p not in params]
        if missing:
            raise ModelError(f"{source}: knob {key} is missing parameter {missing[0]}")
        unknown = [p for p in params if p not in PARAM_NAMES]
        if unknown:
            raise ModelError(f"{source}: knob {key} has unknown parameter {unknown[0]!r}")
        values = {p: _num(params[p], f"knob {key} parameter {p}") for p in params}
        try:
            knobs[int(key)] = KnobModel(**values)
        except ModelError as exc:
            raise ModelError(f"{source}: knob {key}: {exc}") from None
    geometry = None
    if data.get("geometry") is not None:
        g = data["geometry"]
        if not isinstance(g, dict) or "beta_catheter_mm" not in g or "beta_knob_mm" not in g:
            raise ModelError(f"{source}: \"geometry\" needs beta_catheter_mm and beta_knob_mm")
        try:
            geometry = Geometry(_num(g["beta_catheter_mm"], "geometry beta_catheter_mm"),
                                _num(g["beta_knob_mm"], "geometry beta_knob_mm"))
        except ModelError as exc:
            raise ModelError(f"{source}: {exc}") from None
    effects = []
    for i, e in enumerate(data.get("effects") or []):
        if not isinstance(e, dict) or not isinstance(e.get("name"), str):
            raise ModelError(f"{source}: effect #{i + 1} needs a \"name\"")
        params = e.get("params") or {}
        if not isinstance(params, dict):
            raise ModelError(f"{source}: effect {e['name']!r}: \"params\" must be an object")
        form = e.get("form") or ""
        if not isinstance(form, str):
            raise ModelError(f"{source}: effect {e['name']!r}: \"form\" must be a string")
        effects.append(EffectSpec(e["name"], {k: _num(v, f"effect {e['name']} parameter {k}")
                                              for k, v in params.items()}, form))
    meta = data.get("meta") or {}
    if not isinstance(meta, dict):
        raise ModelError(f"{source}: \"meta\" must be an object")
    ident: dict[int, KnobIdentification] = {}
    for key, d in (data.get("identification") or {}).items():
        if key not in ("1", "2") or not isinstance(d, dict):
            raise ModelError(f"{source}: bad \"identification\" entry {key!r}")
        try:
            ident[int(key)] = _identification_of(d, source, key)
        except KeyError as exc:
            raise ModelError(f"{source}: identification of knob {key} is missing {exc.args[0]}") from None
        except ModelError as exc:
            if str(exc).startswith(str(source)):
                raise
            raise ModelError(f"{source}: knob {key}'s {exc}") from None
    return Model(knobs, geometry, tuple(effects), meta, ident)


def _identification_of(d: dict, source: str, key: str) -> KnobIdentification:
    """A knob's identification from its model-file entry."""
    where = f"{source}: knob {key} identification"

    def estimates(value: object, what: str) -> dict:
        if value is None:
            return {}
        if not isinstance(value, dict) or not all(isinstance(v, dict) for v in value.values()):
            raise ModelError(f"{where}: \"{what}\" must map names to intervals")
        return {str(n): Estimate.from_dict(v, f"{where} {what} {n}") for n, v in value.items()}

    sign = d.get("current_sign")
    return KnobIdentification(
        q_min=_num(d["q_min"], "identification q_min"), q_max=_num(d["q_max"], "identification q_max"),
        method=str(d.get("method", "tip")),
        rmse=None if d.get("rmse") is None else _num(d["rmse"], "identification rmse"),
        estimates=estimates(d.get("estimates"), "estimates"),
        calibration=Calibration(
            current_sign=None if sign is None else str(sign),
            current_edges=estimates(d.get("current_edges"), "current_edges"),
            slope_dead_zone=_num(d.get("slope_dead_zone", 0.0), "identification slope_dead_zone"),
            **{name: None if d.get(name) is None else _num(d[name], f"identification {name}")
               for name in Calibration.OPTIONAL}))


def model_to_dict(model: Model) -> dict:
    """The JSON-ready dict of a model (docs/design.md section 6)."""
    out: dict = {"format": MODEL_FORMAT, "version": MODEL_VERSION,
                 "knobs": {str(k): v.params() for k, v in model.knobs.items()}}
    if model.geometry is not None:
        out["geometry"] = {"beta_catheter_mm": model.geometry.beta_catheter_mm,
                           "beta_knob_mm": model.geometry.beta_knob_mm}
    if model.effects:
        out["effects"] = [{"name": e.name, **({"form": e.form} if e.form else {}), "params": dict(e.params)}
                          for e in model.effects]
    if model.meta:
        out["meta"] = dict(model.meta)
    if model.identification:
        out["identification"] = {str(k): _identification_dict(v) for k, v in model.identification.items()}
    return out


def _identification_dict(v: KnobIdentification) -> dict:
    out: dict = {"q_min": v.q_min, "q_max": v.q_max, "method": v.method, "rmse": v.rmse,
                 "estimates": {n: e.to_dict() for n, e in v.estimates.items()}}
    # a model file keeps the calibration's fields beside the rest of the identification (design section 6)
    c = v.calibration
    if c.current_sign is not None:
        out["current_sign"] = c.current_sign
        out["current_edges"] = {n: e.to_dict() for n, e in c.current_edges.items()}
        out["slope_dead_zone"] = c.slope_dead_zone
    out.update({name: getattr(c, name) for name in Calibration.OPTIONAL if getattr(c, name) is not None})
    return out


def load_model(path: str | os.PathLike) -> Model:
    """Read and validate a model JSON file.

    Raises
    ------
    ModelError
        Missing file, invalid JSON, wrong format or version, invalid parameters.
    """
    p = Path(path)
    if not p.exists():
        raise ModelError(f"{path}: no such model file")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelError(f"{path}: cannot read the model ({exc})") from None
    if not text.strip():
        raise ModelError(f"{path}: empty model file")
    try:
        data = json.loads(text, parse_constant=lambda c: float(c))
    except json.JSONDecodeError as exc:
        raise ModelError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    return model_from_dict(data, source=str(path))


def dumps_model(model: Model) -> str:
    """JSON text of a model (stable key order, so the same model gives the same bytes)."""
    return json.dumps(model_to_dict(model), indent=2, allow_nan=False) + "\n"


def save_model(path: str | os.PathLike, model: Model, inputs: Iterable[str | os.PathLike] = ()) -> None:
    """Write a model JSON file atomically."""
    atomic_write_text(path, dumps_model(model), inputs=inputs)


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 of a file, for the provenance in model metadata."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def provenance(source: str | os.PathLike | None, **extra: object) -> dict:
    """Model metadata: the source file, its hash, its modification time and no wall-clock time.

    ``source_modified`` is when the source file was last written (UTC); the model records no time
    of its own making, so that the same command on the same input gives the same bytes.
    """
    meta: dict = {}
    if source is not None:
        meta["source"] = Path(source).name
        meta["sha256"] = file_sha256(source)
        mtime = os.stat(source).st_mtime
        meta["source_modified"] = _dt.datetime.fromtimestamp(mtime, _dt.timezone.utc).replace(
            microsecond=0).isoformat()
    meta.update({k: v for k, v in extra.items() if v is not None})
    return meta
