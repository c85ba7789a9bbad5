"""Protocol files: CSV for the technician's spreadsheet, JSON for programs, Markdown to print.

Every export lists the points in measurement order (:data:`~.core.ORDER_RULE`). The CSV
has columns ``gamma_deg, theta_deg, purpose, power`` with ``power`` left empty: filled in,
the same file is a measurement table that ``irreflect fit`` reads directly (the reader
ignores the ``purpose`` column).
"""

from __future__ import annotations

import io
import math
from dataclasses import replace
from pathlib import Path

import pandas as pd

from .. import schema as sc
from .._atomic import atomic_path
from .._inputs import parse_json, read_bytes
from .._jsonio import dumps
from ..errors import IrreflectError, unknown_name
from ..validation import check_output_path
from .core import ORDER_RULE, Protocol, protocol_from_frame

SCHEMA_VERSION = 1
FORMATS = ("csv", "json", "md")
CONVENTION = (
    "angles in degrees from the surface normal, in the plane of incidence; gamma (angle of "
    "incidence) negative on the source side; theta (receiver) signed, the mirror direction "
    "is theta = -gamma"
)


def _angle(x: float) -> str:
    """An angle as short text: 20, -70, 64.158."""
    return f"{float(x):.6g}"


def _ordered(protocol: Protocol) -> Protocol:
    return protocol if protocol.order == "measurement" else protocol.in_measurement_order()


def to_csv_text(protocol: Protocol) -> str:
    """CSV with ``gamma_deg, theta_deg, purpose, power`` (power empty), measurement order."""
    p = _ordered(protocol)
    df = pd.DataFrame({
        "gamma_deg": [_angle(g) for g in p.gamma_deg],
        "theta_deg": [_angle(t) for t in p.theta_deg],
        "purpose": list(p.purpose),
        "power": [""] * p.n_points,
    })
    return df.to_csv(index=False, lineterminator="\n")


def to_dict(protocol: Protocol) -> dict:
    """The JSON document (schema version :data:`SCHEMA_VERSION`)."""
    p = _ordered(protocol)

    def num(x):
        x = float(x)
        return None if math.isnan(x) else x

    return {
        "schema_version": SCHEMA_VERSION,
        "kind": "irreflect-protocol",
        "name": p.name,
        "protocol_kind": p.kind,
        "n_points": p.n_points,
        "units": {"gamma_deg": "degree", "theta_deg": "degree",
                  "power": "the detector's unit (any, the same for every point)"},
        "convention": CONVENTION,
        "tool_limits": {"theta_min_deg": num(p.theta_min), "theta_max_deg": num(p.theta_max)},
        "rule": p.rule,
        "order_rule": ORDER_RULE,
        "settings": p.settings,
        "points": [
            {"step": i + 1, "gamma_deg": float(g), "theta_deg": float(t), "purpose": pur,
             "requested_theta_deg": num(r), "adjustment": adj}
            for i, (g, t, pur, r, adj) in enumerate(zip(
                p.gamma_deg, p.theta_deg, p.purpose, p.requested_theta_deg, p.adjustment,
                strict=True))
        ],
        "notes": list(p.notes),
    }


def to_json_text(protocol: Protocol) -> str:
    return dumps(to_dict(protocol))


def to_markdown(protocol: Protocol) -> str:
    """A printable checklist with an empty measured-power column."""
    p = _ordered(protocol)
    lines = [f"# Measurement protocol: {p.name}", ""]
    if math.isfinite(p.theta_min):
        lines.append(f"Receiver range of the tool: theta from {_angle(p.theta_min)} to "
                     f"{_angle(p.theta_max)} deg. ")
    lines += [
        f"Convention: {CONVENTION}.",
        "",
        f"{p.n_points} points, {len(p.gammas)} angle(s) of incidence, in measurement order: set "
        "each gamma once, then sweep the receiver in the order listed.",
        "",
        "| done | step | gamma (deg) | theta (deg) | purpose | measured power |",
        "|:---:|---:|---:|---:|---|---|",
    ]
    for i, (g, t, pur) in enumerate(zip(p.gamma_deg, p.theta_deg, p.purpose, strict=True)):
        lines.append(f"| [ ] | {i + 1} | {_angle(g)} | {_angle(t)} | {pur} |  |")
    lines += ["", f"Rule: {p.rule}"]
    if p.notes:
        lines += ["", "Notes:"] + [f"- {n}" for n in p.notes]
    lines += [
        "",
        "Then copy the powers into the `power` column of the protocol's CSV (same order) and "
        "run `irreflect fit PROTOCOL.csv`.",
        "",
    ]
    return "\n".join(lines)


def render(protocol: Protocol, fmt: str = "csv") -> str:
    """The protocol as text in ``fmt`` (``csv``, ``json`` or ``md``)."""

    renderers = {"csv": to_csv_text, "json": to_json_text, "md": to_markdown}
    if fmt not in renderers:
        raise unknown_name("protocol format", fmt, renderers)
    return renderers[fmt](protocol)


def format_from_path(path, default: str = "csv") -> str:
    """The format a file name asks for (``.csv``, ``.json``, ``.md``), else ``default``."""
    suffix = Path(path).suffix.lower().lstrip(".")
    return {"csv": "csv", "json": "json", "md": "md", "markdown": "md"}.get(suffix, default)


def write_protocol(protocol: Protocol, path, fmt: str | None = None) -> Path:
    """Write a protocol atomically; the format follows ``fmt`` or the file's extension."""
    protocol = as_protocol(protocol)
    path = check_output_path(path, "file", "--out")
    text = render(protocol, fmt or format_from_path(path))
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


#: Protocol files larger than this, or with more points, are refused (a protocol lists tens
#: of points; every one is fitted).
MAX_PROTOCOL_BYTES = 16 * 2**20
MAX_PROTOCOL_POINTS = 10_000
_EXPECTED = "a protocol CSV or JSON (written by 'irreflect protocol')"
_POINT = sc.Table({
    "step": sc.Integer(lo=1), "gamma_deg": sc.Number(lo=-90, hi=90, lo_open=True, hi_open=True),
    "theta_deg": sc.Number(lo=-90, hi=90, lo_open=True, hi_open=True),
    "purpose": sc.Text(max_len=64), "requested_theta_deg": sc.Nullable(sc.Number()),
    "adjustment": sc.Text(max_len=64), "power": sc.Nullable(sc.Number()),
}, required=("gamma_deg", "theta_deg"))
#: The declared schema of a protocol JSON document (:func:`to_dict`).
PROTOCOL_SCHEMA = sc.Table({
    "schema_version": sc.Integer(), "kind": sc.Choice(options=("irreflect-protocol",)),
    "name": sc.Text(max_len=200), "protocol_kind": sc.Text(max_len=64),
    "n_points": sc.Integer(lo=0), "units": sc.Document(), "convention": sc.Text(max_len=2000),
    "tool_limits": sc.Table({"theta_min_deg": sc.Nullable(sc.Number(lo=-90, hi=90)),
                             "theta_max_deg": sc.Nullable(sc.Number(lo=-90, hi=90))}),
    "rule": sc.Text(max_len=10_000, multiline=True), "order_rule": sc.Text(max_len=10_000),
    "settings": sc.Document(), "points": sc.ListOf(_POINT, min_items=1, max_items=MAX_PROTOCOL_POINTS),
    "notes": sc.ListOf(sc.Text(max_len=10_000, multiline=True), max_items=10_000),
}, required=("kind", "schema_version", "points"))


def read_protocol(path) -> Protocol:
    """Read a protocol written by :func:`write_protocol` (CSV or JSON), or any CSV with
    ``gamma_deg, theta_deg`` (optional ``purpose``; other columns ignored)."""
    raw = read_bytes(path, "protocol", _EXPECTED, MAX_PROTOCOL_BYTES)
    path = Path(path)
    if path.suffix.lower() == ".json":
        return _protocol_from_json(path, raw)
    try:
        df = pd.read_csv(io.BytesIO(raw), dtype=str, comment="#", skipinitialspace=True,
                         keep_default_na=False)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError,
            ValueError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        first = first.replace("Error tokenizing data. C error: ", "")
        raise IrreflectError(f"{path}: cannot be read as a CSV protocol ({first}): expected "
                             "a CSV or JSON file as 'irreflect protocol --out' writes, with "
                             "columns gamma_deg, theta_deg") from None
    if len(df) > MAX_PROTOCOL_POINTS:
        raise IrreflectError(f"{path}: {len(df)} points is more than a protocol may list "
                             f"({MAX_PROTOCOL_POINTS}): a protocol names the few settings to "
                             "measure; give the dense scan as DENSE instead")
    return protocol_from_frame(df, str(path), name=path.stem)


def _protocol_from_json(path: Path, raw: bytes) -> Protocol:
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise IrreflectError(f"{path}: not UTF-8 text; expected {_EXPECTED}") from None
    doc = parse_json(text, str(path), _EXPECTED)
    if not isinstance(doc, dict) or doc.get("kind") != "irreflect-protocol":
        raise IrreflectError(f"{path}: not an irreflect protocol (no \"kind\": "
                             "\"irreflect-protocol\"): export one with 'irreflect protocol'")
    if doc.get("schema_version") != SCHEMA_VERSION:
        raise IrreflectError(f"{path}: protocol schema version {doc.get('schema_version')!r} "
                             f"is not supported; this irreflect reads version {SCHEMA_VERSION}")
    doc = sc.validate(PROTOCOL_SCHEMA, doc, str(path))
    df = pd.DataFrame(doc["points"])
    proto = protocol_from_frame(df, str(path), name=doc.get("name") or path.stem)
    limits = doc.get("tool_limits") or {}
    return replace(
        proto, kind=doc.get("protocol_kind", "file"), rule=doc.get("rule", ""),
        settings=doc.get("settings") or {}, notes=tuple(doc.get("notes") or ()),
        theta_min=_or_nan(limits.get("theta_min_deg")),
        theta_max=_or_nan(limits.get("theta_max_deg")),
    )


def _or_nan(value) -> float:
    return float("nan") if value is None else float(value)


def as_protocol(obj) -> Protocol:
    """Accept a Protocol, a DataFrame with gamma_deg/theta_deg, or a path."""
    if isinstance(obj, Protocol):
        return obj
    if isinstance(obj, pd.DataFrame):
        return protocol_from_frame(obj)
    if isinstance(obj, str | Path):
        return read_protocol(obj)
    raise IrreflectError(
        f"expected a protocol (Protocol, table or path), found {type(obj).__name__}"
    )
