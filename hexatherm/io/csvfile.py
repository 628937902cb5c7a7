"""CSV readers of ball centres and probed points, and the CSV primitives that the
thermocouple log (:mod:`hexatherm.io.temperatures`) shares.

Centres and points files share the header ``label,ball,x,y,z,time``; centres may
add ``diameter``, points ``i,j,k`` (probing direction). Which of the two a file
holds is told by (in this order) its extra columns, its name (``centres``,
``centers`` or ``points`` in it), or its content (at least half the steps and balls
with one row means centres). ``time`` is an ISO 8601 timestamp or a number of
seconds, the same kind on every row.

Errors name the file, the line (header = line 1) and the column. What is refused:

* files that are not regular, or larger than
  :data:`~hexatherm.io.files.MAX_MEASUREMENT_BYTES`; text that is not UTF-8;
* a file whose last line has no line break: it may be cut short, in the middle of
  its last number (``allow_truncated`` drops that line, with an
  :class:`~hexatherm.errors.InputWarning`);
* ISO times that are not ``YYYY-MM-DDTHH:MM[:SS[.f]]`` with two-digit fields and
  an optional offset (``Z``, ``+HH:MM``, ``+HHMM``, ``+HH``): ``T10:1``, ``09:35:5``,
  ``2019-12-2`` and a date alone are refused rather than guessed; a file mixing times
  with and without a UTC offset (:func:`~hexatherm.io.records.check_time_zones`
  compares files); any year from 1 to 9999;
* non-finite numbers (``nan``, ``inf``, ``1e400``); a ``u_um`` or ``u_x_um`` ..
  ``u_z_um`` outside [:data:`U_UM_MIN`, :data:`U_UM_MAX`] um, a ``diameter`` <= 0,
  a ``form_um`` < 0, an ``n`` that is not a whole number >= 1; temperatures outside
  [-60, 150] degC (kelvin?);
* a ball measured twice in one step (two groups of rows, or two centre rows) and
  a point label seen twice (:func:`~hexatherm.io.records.check_groups`;
  ``keep_later`` keeps the later group).
"""

from __future__ import annotations

import io
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd

from hexatherm.core.plan import NAME_PATTERN
from hexatherm.errors import InputError
from hexatherm.io import records as records_module
from hexatherm.io.csvcolumns import (
    ASCII_BLANKS,
    column_numbers,
    column_times,
    drop_blank_rows,
    iso_times_from_bytes,
    times_and_names_from_bytes,
)
from hexatherm.io.csvout import csv_text
from hexatherm.io.csvtext import complete_lines, csv_frame, decode_text
from hexatherm.io.files import read_bytes
from hexatherm.io.records import RecordKind, Records, check_groups, seconds_to_iso

BASE_COLUMNS = ("label", "ball", "x", "y", "z", "time")
#: a centre's covariance, CMM frame: standard uncertainties per axis (um) and correlations
CENTRE_COVARIANCE = ("u_x_um", "u_y_um", "u_z_um", "r_xy", "r_xz", "r_yz")
CENTRE_EXTRA = ("diameter", "form_um", "n", "u_um", *CENTRE_COVARIANCE)  # but diameter: extensions
POINT_EXTRA = ("i", "j", "k")


#: Decimals of the correlations ``r_*`` a centres file is written with, and how far below
#: zero the smallest eigenvalue of a file's correlation matrix may be (that rounding)
CORRELATION_DECIMALS = 6
CORRELATION_SLACK = 1e-5

#: The largest and smallest standard uncertainty ``u_um`` of a centre accepted, um: below a
#: nanometre no CMM knows a centre (1e-9 made every U 0 and every target conform; the
#: registration's weights stop there too)
U_UM_MAX, U_UM_MIN = 1000.0, 1e-3


def _check_header(frame: pd.DataFrame, path: str, extras: tuple[str, ...]) -> None:
    columns = list(frame.columns)
    if tuple(columns[:6]) != BASE_COLUMNS:
        raise InputError(
            f"header must start with {','.join(BASE_COLUMNS)}, got {','.join(columns)}",
            path=path,
            line=1,
        )
    for column in columns[6:]:
        if column not in extras:
            raise InputError(
                f"unknown column {column!r}; allowed after the first six: {', '.join(extras)}",
                path=path,
                line=1,
                field=column,
            )


def _names(frame: pd.DataFrame, column: str, path: str) -> npt.NDArray[np.str_]:
    values = frame[column].to_numpy(dtype=str)
    ok = np.array([bool(NAME_PATTERN.fullmatch(v)) for v in values], dtype=bool)
    if not np.all(ok):
        row = int(np.argmax(~ok))
        raise InputError(
            f"{str(values[row])!r} must match [A-Za-z0-9-]+",
            path=path,
            line=int(frame.index[row]),
            field=column,
        )
    return values


def _kind(columns: list[str], path: str, label: npt.ArrayLike, ball: npt.ArrayLike) -> RecordKind:
    """Centres or points, told by the extra columns, the file's name, or at least half of
    the steps' balls with one row (centres)."""
    extra = set(columns[6:])
    if extra & set(CENTRE_EXTRA):
        return "centres"
    if extra & set(POINT_EXTRA):
        return "points"
    name = Path(path).name.lower()
    if "centre" in name or "center" in name:
        return "centres"
    if "point" in name:
        return "points"
    counts = pd.DataFrame({"label": label, "ball": ball}).groupby(["label", "ball"]).size()
    return "centres" if len(counts) and (counts == 1).mean() >= 0.5 else "points"


def read_measurement_csv(
    path: str | os.PathLike[str],
    kind: RecordKind | None = None,
    *,
    allow_truncated: bool = False,
    keep_later: bool = False,
) -> Records:
    """Read a centres or points CSV file into :class:`Records`.

    Parameters
    ----------
    path : str or path-like
        The file.
    kind : {"centres", "points"}, optional
        What the file holds; told from its columns, name or content when not given.
    allow_truncated : bool, optional
        Drop a last line without a line break (with an :class:`InputWarning`) instead
        of refusing the file.
    keep_later : bool, optional
        Keep the later group of a ball measured twice in one step (with an
        :class:`InputWarning`) instead of refusing the file; see
        :func:`~hexatherm.io.records.check_groups`.

    Raises
    ------
    InputError
        Naming the file, the line and the field (see the module's list).
    """
    path = os.fspath(path)
    raw = read_bytes(path)
    fast = _fast_measurement_csv(raw, path, kind)
    if fast is not None:
        return check_groups(fast, keep_later=keep_later)
    text = complete_lines(decode_text(raw, path), path, allow_truncated)
    frame = csv_frame(text, path)
    _check_header(frame, path, CENTRE_EXTRA + POINT_EXTRA)
    frame = drop_blank_rows(frame)
    if frame.empty:
        raise InputError("no data rows", path=path, line=2)
    kind = kind or _kind(list(frame.columns), path, frame["label"], frame["ball"])
    extras = CENTRE_EXTRA if kind == "centres" else POINT_EXTRA
    misplaced = [c for c in frame.columns[6:] if c not in extras]
    if misplaced:
        raise InputError(
            f"column {misplaced[0]!r} does not belong in a {kind} file",
            path=path,
            line=1,
            field=misplaced[0],
        )
    label, ball = _names(frame, "label", path), _names(frame, "ball", path)
    xyz = np.column_stack([column_numbers(frame, c, path) for c in ("x", "y", "z")])
    time, time_kind, aware = column_times(frame, path)
    lines = frame.index.to_numpy(dtype=np.int64)
    diameter = ijk = None
    extra: dict[str, object] = {}
    if kind == "centres":
        checked: dict[str, npt.NDArray[np.float64] | None] = {}
        for column in CENTRE_EXTRA:
            if column in frame.columns:
                checked[column] = column_numbers(frame, column, path, allow_empty=True)
        _check_centre_columns(checked, lines, path, frame)
        diameter = checked.pop("diameter", None)
        extra = _centre_extra({c: v for c, v in checked.items() if v is not None}, lines, path)
    elif all(c in frame.columns for c in POINT_EXTRA):
        ijk = np.column_stack(
            [column_numbers(frame, c, path, allow_empty=True) for c in POINT_EXTRA]
        )
    elif any(c in frame.columns for c in POINT_EXTRA):
        raise InputError("give all of i, j, k or none", path=path, line=1)
    records = Records(
        path=path,
        kind=kind,
        label=label,
        ball=ball,
        xyz_mm=xyz,
        time_s=time,
        time_kind=time_kind,
        line=lines,
        diameter_mm=diameter,
        ijk=ijk,
        extra=extra,
        time_aware=aware,
    )
    return check_groups(records, keep_later=keep_later)


#: What the extension columns of a centres file must hold: (test, requirement)
_CENTRE_RULES: dict[str, tuple[Callable[[npt.NDArray[np.float64]], npt.NDArray[np.bool_]], str]] = {
    "diameter": (lambda v: v > 0, "a diameter must be > 0 mm"),
    "form_um": (lambda v: v >= 0, "a form error must be >= 0 um"),
    "n": (lambda v: (v >= 1) & (v == np.round(v)), "a point count must be a whole number >= 1"),
    **dict.fromkeys(
        ("u_um", "u_x_um", "u_y_um", "u_z_um"),
        (
            lambda v: (v >= U_UM_MIN) & (v <= U_UM_MAX),
            f"a standard uncertainty must be >= {U_UM_MIN:g} um (no CMM knows a ball "
            f"centre better than a nanometre) and <= {U_UM_MAX:g} um",
        ),
    ),
    **dict.fromkeys(
        ("r_xy", "r_xz", "r_yz"),
        (lambda v: np.abs(v) <= 1, "a correlation must be within [-1, 1]"),
    ),
}


def _centre_extra(
    values: dict[str, npt.NDArray[np.float64]], lines: npt.NDArray[np.int64], path: str
) -> dict[str, object]:
    """The ``extra`` of a centres file's records from its checked extension columns:
    ``form_um``, ``n``, ``u_um`` as given; the covariance columns as ``cov_centre_mm2``
    (N, 3, 3), NaN for a row without them, and ``cov_from_file`` (N,) where given.

    The three ``u_*_um`` come together; the correlations (all three or none) only with
    them, and zero when left out. A row fills all of them or none, and its correlations
    must make a positive semi-definite matrix: InputError naming line and field."""
    extra: dict[str, object] = {c: values[c] for c in ("form_um", "n", "u_um") if c in values}
    given = [c for c in CENTRE_COVARIANCE if c in values]
    if not given:
        return extra
    axes, correlations = CENTRE_COVARIANCE[:3], CENTRE_COVARIANCE[3:]
    for group in (axes, correlations):
        if any(c in values for c in group) and not all(c in values for c in group):
            missing = next(c for c in group if c not in values)
            raise InputError(
                f"give {', '.join(group)} together (the covariance of a centre)",
                path=path,
                line=1,
                field=missing,
            )
    if correlations[0] in values and axes[0] not in values:
        raise InputError(
            f"correlations need the standard uncertainties {', '.join(axes)}",
            path=path,
            line=1,
            field=correlations[0],
        )
    table = np.column_stack([values[c] for c in given])
    present = ~np.isnan(table)
    partial = present.any(axis=1) & ~present.all(axis=1)
    if np.any(partial):
        row = int(np.argmax(partial))
        field = given[int(np.argmax(~present[row]))]
        raise InputError(
            f"{field} is empty where other covariance columns are given: give all of "
            f"{', '.join(given)} or none",
            path=path,
            line=int(lines[row]),
            field=field,
        )
    n = len(table)
    rho = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    if correlations[0] in values:
        for (a, b), column in zip(((0, 1), (0, 2), (1, 2)), correlations, strict=True):
            rho[:, a, b] = rho[:, b, a] = values[column]
    rows = present.all(axis=1)
    with np.errstate(invalid="ignore"):
        smallest = np.full(n, np.nan)
        if rows.any():
            smallest[rows] = np.linalg.eigvalsh(rho[rows])[:, 0]
    invalid = rows & (smallest < -CORRELATION_SLACK)
    if np.any(invalid):
        row = int(np.argmax(invalid))
        raise InputError(
            "r_xy, r_xz, r_yz make no correlation matrix (not positive semi-definite)",
            path=path,
            line=int(lines[row]),
            field="r_xy",
        )
    u_mm = np.column_stack([values[c] for c in axes]) * 1e-3
    extra["cov_centre_mm2"] = cov = u_mm[:, :, None] * rho * u_mm[:, None, :]
    extra["cov_from_file"] = rows
    if "u_um" in values:
        records_module.check_u_covariance(values["u_um"], cov, lines, path)
    return extra


def _check_centre_columns(
    columns: dict[str, npt.NDArray[np.float64] | None],
    lines: npt.NDArray[np.int64],
    path: str,
    frame: pd.DataFrame | None = None,
) -> None:
    """InputError at the first value of an extension column out of its range (empty
    values, NaN here, are allowed: not given)."""
    for column, values in columns.items():
        if values is None:
            continue
        test, requirement = _CENTRE_RULES[column]
        with np.errstate(invalid="ignore"):
            bad = ~test(values) & ~np.isnan(values)
        if np.any(bad):
            row = int(np.argmax(bad))
            shown = frame[column].iloc[row] if frame is not None else str(float(values[row]))
            raise InputError(
                f"{requirement}, got {shown!r}", path=path, line=int(lines[row]), field=column
            )


#: rows of a measurement file parsed at a time: a scanning probe's millions of points are
#: read in bounded memory (their times and names are Python strings only a chunk at a time)
CHUNK_ROWS = 1 << 17


class _Unclean(Exception):
    """A chunk the fast reader leaves to the general one."""


def _fast_measurement_csv(raw: bytes, path: str, kind: RecordKind | None) -> Records | None:
    """:func:`read_measurement_csv` for a clean file, or None: then the general reader must.

    Clean: ASCII without NUL or quotes, every line ended (LF or CRLF), a header of known
    column names without blanks, and every value that the general reader would take
    without complaint and without stripping blanks (names, times), with no empty or
    non-finite number. The file is parsed from its bytes by pandas' C parser, the numbers
    straight to floats (the converter of ``pd.to_numeric``, correctly rounded), in chunks
    of :data:`CHUNK_ROWS` rows whose strings are turned into arrays at once. Anything else
    (and any error) is left to the general reader, so that results and errors are the
    same.
    """
    if not raw.endswith(b"\n") or b'"' in raw or b"\x00" in raw or not raw.isascii():
        return None
    if b"\r" in raw:
        raw = raw.replace(b"\r\n", b"\n")
        if b"\r" in raw:
            return None
    columns = raw[: raw.find(b"\n")].decode("ascii").split(",")
    known = set(BASE_COLUMNS + CENTRE_EXTRA + POINT_EXTRA)
    if (
        tuple(columns[:6]) != BASE_COLUMNS
        or not set(columns) <= known
        or len(set(columns)) != len(columns)
    ):
        return None
    numeric = [c for c in columns if c not in ("label", "ball", "time")]
    # ISO times of one layout and the names straight from the bytes (no Python string per
    # row; pandas then reads the numbers only), else the times alone, else pandas reads
    # them as text; the cut is None where a line holds a blank (the header, of known
    # names, holds none), else no value can hold a blank to strip: the parser need not
    # look for them
    time_column = BASE_COLUMNS.index("time")
    cut = times_and_names_from_bytes(raw, time_column, len(columns), (0, 1), True)
    blank_free = cut is not None or _blank_free(raw)
    times = cut[:2] if cut is not None else None
    if blank_free and cut is None:
        times = iso_times_from_bytes(raw, time_column, len(columns))
    # names as categories: each chunk's distinct names become strings, its rows codes (no
    # Python string per row)
    dtypes: dict[str, str | type] = {"label": "category", "ball": "category", "time": object}
    dtypes.update(dict.fromkeys(numeric, float))
    read = columns if times is None else [c for c in columns if c != "time"]
    if cut is not None:
        read = numeric
    try:
        chunks = pd.read_csv(
            io.BytesIO(raw),  # shares the bytes, no copy
            encoding="utf-8",
            dtype={c: dtypes[c] for c in read},
            usecols=None if times is None else read,
            keep_default_na=False,
            na_values=dict.fromkeys(numeric, [""]),
            skipinitialspace=not blank_free,
            skip_blank_lines=False,
            engine="c",
            chunksize=CHUNK_ROWS,
        )
        parts = []
        with chunks:
            for frame in chunks:
                parts.append(_clean_chunk(frame, read, numeric, blank_free, path))
    except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError, _Unclean, InputError):
        return None
    if times is not None:
        for part in parts:
            part.update(time_kind="iso", aware=times[1])
    if not parts or len({(p["time_kind"], p["aware"]) for p in parts}) != 1:
        return None  # no rows, or times of different kinds: the general reader says
    if cut is not None:
        label, ball = cut[2]
    else:
        label, ball = (_spread_names([p[key] for p in parts]) for key in ("label", "ball"))
    time_s = times[0] if times is not None else np.concatenate([p["time"] for p in parts])
    if time_s.size != label.size:
        return None
    # the coordinates (and normals) were stacked chunk by chunk: one copy of them, here
    values = {c: np.concatenate([p["values"][c] for p in parts]) for c in parts[0]["values"]}
    xyz = np.concatenate([p["xyz"] for p in parts])
    normals = None if parts[0]["ijk"] is None else np.concatenate([p["ijk"] for p in parts])
    time_kind, aware = parts[0]["time_kind"], parts[0]["aware"]
    del parts
    lines = np.arange(time_s.size, dtype=np.int64) + 2
    kind = kind or _kind(columns, path, label, ball)
    extras = CENTRE_EXTRA if kind == "centres" else POINT_EXTRA
    if any(c not in extras for c in columns[6:]):
        return None
    diameter = ijk = None
    extra: dict[str, object] = {}
    try:
        if kind == "centres":
            _check_centre_columns({c: values.get(c) for c in CENTRE_EXTRA}, lines, path)
            diameter = values.get("diameter")
            extra = _centre_extra(values, lines, path)
    except InputError:
        return None
    if kind == "points" and normals is not None:
        ijk = normals
    elif kind == "points" and any(c in columns for c in POINT_EXTRA):
        return None
    return Records(
        path=path,
        kind=kind,
        label=label,
        ball=ball,
        xyz_mm=xyz,
        time_s=time_s,
        time_kind=time_kind,
        line=lines,
        diameter_mm=diameter,
        ijk=ijk,
        extra=extra,
        time_aware=aware,
    )


#: bytes :func:`_blank_free` looks at in one go (its temporaries stay small)
_BLANK_SCAN = 1 << 22


def _blank_free(raw: bytes) -> bool:
    """Whether ``raw`` holds none of :data:`ASCII_BLANKS`: one pass over the bytes (every
    blank is below ``!``, and of those a clean file holds only line feeds), instead of a
    search for each blank."""
    data = np.frombuffer(raw, dtype=np.uint8)
    for start in range(0, data.size, _BLANK_SCAN):
        part = data[start : start + _BLANK_SCAN]
        if np.count_nonzero(part < 33) != np.count_nonzero(part == 10):
            # a blank, or another control byte: the search for each blank decides
            return not any(c.encode() in raw for c in ASCII_BLANKS)
    return True


def _spread_names(
    chunks: list[tuple[npt.NDArray[np.object_], npt.NDArray[np.integer]]],
) -> npt.NDArray[np.str_]:
    """Every row's name (a str array) from each chunk's distinct names and codes: the
    names of all chunks made one list, each converted once, then spread."""
    index: dict[str, int] = {}
    codes = []
    for names, chunk_codes in chunks:
        where = np.array([index.setdefault(name, len(index)) for name in names], dtype=np.intp)
        codes.append(where[chunk_codes])
    return np.asarray(list(index), dtype=str)[np.concatenate(codes)]


def _clean_chunk(
    frame: pd.DataFrame, columns: list[str], numeric: list[str], blank_free: bool, path: str
) -> dict:
    """One chunk of :func:`_fast_measurement_csv` as arrays; :class:`_Unclean` (or an
    InputError) when the general reader must read the file."""
    if frame.empty or list(frame.columns) != columns:
        raise _Unclean
    with_times = "time" in columns  # else the times were read from the bytes
    if with_times and frame["time"].isna().any():
        raise _Unclean  # a short row
    named: dict[str, tuple[npt.NDArray[np.object_], npt.NDArray[np.integer]]] = {}
    for column in ("label", "ball") if "label" in columns else ():  # else cut from the bytes
        names = frame[column].cat.categories.to_numpy(dtype=object)
        codes = frame[column].cat.codes.to_numpy()
        if not all(isinstance(v, str) and NAME_PATTERN.fullmatch(v) for v in names):
            raise _Unclean
        if codes.size and codes.min() < 0:
            raise _Unclean  # a missing name (a short row)
        # each name converted once, then spread (not a million conversions)
        named[column] = (names, codes)  # spread once, for the whole file
    if not blank_free and with_times:
        # a blank somewhere in the file: is it in a time?
        times = frame["time"].to_numpy()
        if not all(isinstance(v, str) and v and v == v.strip() for v in times):
            raise _Unclean
    # else no value can hold a blank to strip; an empty time is refused by column_times
    values = {c: frame[c].to_numpy(dtype=np.float64) for c in numeric}
    if not all(np.isfinite(v).all() for v in values.values()):
        raise _Unclean  # empty or non-finite numbers: the general reader tells them apart
    time, time_kind, aware = column_times(frame, path) if with_times else (None, "iso", None)
    xyz = np.column_stack([values.pop(c) for c in ("x", "y", "z")])
    with_normals = all(c in values for c in POINT_EXTRA)
    ijk = np.column_stack([values.pop(c) for c in POINT_EXTRA]) if with_normals else None
    return {
        **named,
        "values": values,  # the other numbers, by column
        "xyz": xyz,
        "ijk": ijk,
        "time": time,
        "time_kind": time_kind,
        "aware": aware,
    }


def centres_to_csv(records: Records) -> str:
    """Centres CSV text: the contract columns, then ``diameter`` and, when known, the
    extension columns ``form_um``, ``n``, ``u_um`` (written by ``fit-spheres``), at
    the resolution of their unit (:mod:`hexatherm.io.csvout`)."""
    if records.time_kind == "iso":
        times: object = [seconds_to_iso(t) for t in records.time_s]
    else:
        times = records.time_s
    data: dict[str, object] = {
        "label": records.label,
        "ball": records.ball,
        "x": records.xyz_mm[:, 0],
        "y": records.xyz_mm[:, 1],
        "z": records.xyz_mm[:, 2],
        "time": times,
    }
    if records.diameter_mm is not None:
        data["diameter"] = records.diameter_mm
    for column in ("form_um", "n", "u_um"):
        if column in records.extra:
            data[column] = records.extra[column]
    if "cov_centre_mm2" in records.extra:
        cov = np.asarray(records.extra["cov_centre_mm2"], dtype=float)
        u_um = np.sqrt(np.diagonal(cov, axis1=1, axis2=2)) * 1e3
        with np.errstate(invalid="ignore", divide="ignore"):
            rho = cov / (u_um[:, :, None] * u_um[:, None, :] * 1e-6)
        for j, column in enumerate(CENTRE_COVARIANCE[:3]):
            data[column] = np.where(u_um[:, j] > 0, u_um[:, j], np.nan)
        for (a, b), column in zip(((0, 1), (0, 2), (1, 2)), CENTRE_COVARIANCE[3:], strict=True):
            r = np.round(np.clip(rho[:, a, b], -1, 1), CORRELATION_DECIMALS)
            data[column] = np.where(np.isfinite(r), r, np.nan)
    return csv_text(pd.DataFrame(data))
