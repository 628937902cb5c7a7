"""What makes a report a document a lab issues (ISO/IEC 17025:2017, 7.8.2.1): its own
number, its title, its date of issue, the lab, the method, and the identification block
every report prints under its title.

Each document gets its **own number** (:func:`document_number`): ``--report-number``
when given; else the lab file's ``numbering:`` pattern, whose fields are ``{session}``
(the session's ``report_number``, its name without one; a calibration's first session),
``{doc}`` (the document's code, :data:`DOC_CODES`: ``R`` a process report, ``C`` a
calibration, ``D`` a diagnosis), ``{date}`` and ``{time}`` of issue (``YYYYMMDD``,
``HHMMSS``); else a process report takes its session's ``report_number`` (the number the
lab gave that session's report) and a calibration ``<session's number>-C``: never the
session's number itself. A counter (the next free number of the lab's register) is the
lab's quality system's to keep: it gives it with ``--report-number``.

The templates get the identification as variables (:func:`template_variables`): ``lab``
(``lab.name``, ``lab.address``, ``lab.contact``, ``lab.accreditation``: empty texts when
not given), ``document`` (``document.number``, ``document.title``, ``document.issued``,
``document.issue_date``) and ``identification`` (every field by its key, as printed).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta, timezone
from typing import Any

from hexatherm.workflows.report.page import Cell, table
from hexatherm.workflows.report.render import Table

#: the document code of each command's report (``{doc}`` of a numbering pattern)
DOC_CODES = {"report": "R", "calibrate": "C", "diagnose": "D"}
#: each document's title when the lab chooses none (``titles:``, ``--title``)
DEFAULT_TITLES = {
    "report": "Measurement report",
    "calibrate": "Calibration report: hexapod geometry",
    "diagnose": "Diagnosis report",
}
#: the method's reference (the paper hexatherm implements)
METHOD_REFERENCE = (
    "V. J. Kalas, A. Vissi\u00e8re, O. Company, S. Krut, P. Noir\u00e9, T. Roux, F. Pierrot, "
    '"Thermal deflection decoupled 6-DOF pose measurement of hexapods"'
)
#: the statement ISO/IEC 17025 7.8.2.1 l) asks for, on every report
RELATES_ONLY = (
    "The results relate only to the item measured, as received, under the conditions "
    "stated. This report shall not be reproduced except in full."
)


@dataclass(frozen=True)
class Lab:
    """The laboratory, as the templates print it (empty texts: not given)."""

    name: str = ""
    address: str = ""
    contact: str = ""
    accreditation: str = ""


@dataclass(frozen=True)
class Document:
    """One document's identity.

    Attributes
    ----------
    kind : str
        ``report``, ``calibrate`` or ``diagnose``.
    number : str
        Its unique number ("" when none could be given).
    title : str
        The title the lab chose, or :data:`DEFAULT_TITLES`'s.
    issued : str
        Date and time of issue, ISO 8601 with its UTC offset.
    """

    kind: str
    number: str
    title: str
    issued: str

    @property
    def issue_date(self) -> str:
        """The date of issue (``YYYY-MM-DD``)."""
        return self.issued[:10]


def document_number(
    kind: str,
    issued: str,
    option: str | None,
    fields: Mapping[str, object],
    session_numbers: Sequence[str | None],
    session_names: Sequence[str],
) -> str:
    """The document's number (see the module text): ``option``, else ``fields``'
    ``numbering`` pattern, else from the first session's number."""
    if option:
        return option
    first = session_numbers[0] if session_numbers else None
    session = first or (session_names[0] if session_names else "")
    pattern = fields.get("numbering")
    if isinstance(pattern, str):
        stamp = datetime.fromisoformat(issued)
        return pattern.format(
            session=session,
            doc=DOC_CODES[kind],
            date=stamp.strftime("%Y%m%d"),
            time=stamp.strftime("%H%M%S"),
        )
    if first is None:
        return ""
    return first if kind == "report" else f"{first}-{DOC_CODES[kind]}"


def document(
    kind: str,
    issued: str,
    fields: Mapping[str, object],
    session_numbers: Sequence[str | None] = (),
    session_names: Sequence[str] = (),
    number: str | None = None,
    title: str | None = None,
) -> Document:
    """The document ``kind`` issued at ``issued``: its number and title (``number``,
    ``title``: the command line's, over the lab file's ``fields``)."""
    chosen = title or fields.get(f"titles.{kind}") or DEFAULT_TITLES[kind]
    return Document(
        kind,
        document_number(kind, issued, number, fields, session_numbers, session_names),
        str(chosen),
        issued,
    )


def template_variables(doc: Document, fields: Mapping[str, object]) -> dict[str, Any]:
    """What every page's templates are given besides their content: ``lab``,
    ``document`` and ``identification`` (see the module text)."""
    text = {k: f"{v:g}" if isinstance(v, float) else str(v) for k, v in fields.items()}
    text.pop("signatures", None)
    return {
        "lab": Lab(
            text.get("lab", ""),
            text.get("address", ""),
            text.get("contact", ""),
            text.get("accreditation", ""),
        ),
        "document": doc,
        "identification": text,
    }


def offset_time(seconds: float, utc_offset_s: float | None, aware: bool | None) -> str:
    """A measured time (POSIX seconds, UTC) as ISO 8601 with its UTC offset: the
    session's ``utc_offset:`` when it states one, UTC when the files gave offsets;
    without either, the time as the files gave it, marked as of an unknown offset."""
    if utc_offset_s is None and not aware:
        stamp = datetime.fromtimestamp(float(seconds), tz=UTC)
        return stamp.replace(tzinfo=None).isoformat(timespec="seconds") + " (UTC offset unknown)"
    zone = timezone(timedelta(seconds=float(utc_offset_s or 0.0)))
    return datetime.fromtimestamp(float(seconds), tz=zone).isoformat(timespec="seconds")


def span_text(first: str, last: str) -> str:
    """``first`` to ``last``, once when they are the same."""
    return first if first == last else f"{first} to {last}"


def method_text(kind: str, uncertainty: str, fields: Mapping[str, object]) -> list[Cell]:
    """The method (ISO/IEC 17025 7.8.2.1 f and n) as ``(field, text)`` rows' texts:
    the paper, the lab's procedure, the uncertainty's method, deviations."""
    what = {
        "report": "thermal deflection decoupled pose measurement",
        "calibrate": "geometric calibration by weighted least squares on thermal-deflection "
        "decoupled poses",
        "diagnose": "comparison of the measured poses with a digital twin",
    }[kind]
    return [
        f"{what}, after {METHOD_REFERENCE}; implemented by hexatherm",
        str(fields.get("procedure", "no laboratory procedure named (procedure: in the lab file)")),
        uncertainty,
        str(fields.get("deviations", "none")),
    ]


def identification_block(
    doc: Document,
    fields: Mapping[str, object],
    item: str,
    measured: str,
    uncertainty: str,
    results: str,
    authorised: Sequence[tuple[str, str]],
) -> Table:
    """The block under the title: the items of ISO/IEC 17025:2017 7.8.2.1 a-p, each
    named, "not stated" where the lab file and session give nothing."""

    def given(key: str, missing: str = "not stated") -> str:
        value = fields.get(key)
        return (
            missing if value is None else f"{value:g}" if isinstance(value, float) else str(value)
        )

    lab = given("lab")
    if "address" in fields:
        lab += f", {fields['address']}"
    if "accreditation" in fields:
        lab += f" ({fields['accreditation']})"
    customer = given("customer")
    if "customer_address" in fields:
        customer += f", {fields['customer_address']}"
    condition = fields.get("hexapod.condition")
    method, procedure, u_method, deviations = method_text(doc.kind, uncertainty, fields)
    rows: list[Sequence[Cell]] = [
        ["Title", doc.title],
        [
            "Report number",
            doc.number or "none assigned (--report-number, or numbering: in the lab file)",
        ],
        ["Laboratory", lab],
        ["Place of measurement", given("place", given("address"))],
        ["Customer", customer],
        ["Item", item + (f"; condition: {condition}" if condition else "")],
        ["Date of receipt", given("received")],
        ["Date(s) of measurement", measured],
        ["Date of issue", doc.issue_date],
        ["Method", method],
        ["Procedure", procedure],
        ["Deviations from the method", deviations],
        ["Uncertainty", u_method],
        ["Sampling", "not applicable: every pose of the plan was measured"],
        ["Results", results],
        ["Results from external providers", given("external_providers", "none")],
        [
            "Authorised by",
            ", ".join(f"{name} ({role})" for role, name in authorised)
            or "not stated (signatures: in the lab file or session)",
        ],
        ["Validity", RELATES_ONLY],
    ]
    return table([[("", 1), ("", 1)]], rows, numeric_from=99, css="meta ident")
