"""The official QIF 3.0 schema shipped with hexatherm, and safe, streamed XML parsing.

The schema files (``hexatherm/data/qif3/``, Boost licence, unchanged) are compiled once
per process with lxml (libxml2, about a second); :func:`schema` caches the result.
``QIFDocument.xsd`` imports the W3C's XML-Signature schema from the W3C's web site: the
parser that loads the schema never reaches the network, and a resolver hands it the
shipped copy instead.

Every QIF file is parsed by :func:`iter_elements`, which

* opens it through :func:`~hexatherm.io.files.open_bounded` (a regular file, bounded
  size: a 2 GiB file is refused by its size before a byte is read);
* parses it in a stream (lxml's ``iterparse``): memory stays bounded by the largest
  element that the caller keeps, not by the file;
* never loads a DTD, never expands an entity and never reaches the network, and refuses a
  document that declares a DTD (``<!DOCTYPE``: QIF needs none; XML bombs and external
  entities live there) before reading its content;
* turns a syntax error (a file cut short, broken XML) into one
  :class:`~hexatherm.errors.InputError` naming the file, the line and, where known, the
  element.

:func:`check_element` validates one element that hexatherm reads (a global element of
the schema, such as ``SphereFeatureMeasurement`` or ``FileUnits``) against the schema,
where it lies in the file: a value or child out of the schema is refused naming the file,
the line and the element. A whole-document validation (:func:`check_document`) is about 20
times slower than the streamed read (a 3 MB product model: 9 s against 0.4 s; a 100 kB
results file: 0.27 s against 0.012 s), so the readers validate what they read and the
tests validate what hexatherm writes whole.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from lxml import etree

from hexatherm.errors import InputError
from hexatherm.io.files import MAX_MEASUREMENT_BYTES, open_bounded

#: The namespace of QIF 3 documents
QIF_NS = "http://qifstandards.org/xsd/qif3"
#: Where the shipped schema lives
SCHEMA_DIR = Path(__file__).resolve().parent.parent / "data" / "qif3"
#: The address ``QIFDocument.xsd`` imports the XML-Signature schema from, and its copy
_XMLDSIG_URL = "http://www.w3.org/TR/2002/REC-xmldsig-core-20020212/xmldsig-core-schema.xsd"
_XMLDSIG_FILE = SCHEMA_DIR / "QIFLibrary" / "xmldsig-core-schema.xsd"
#: What a parser of anything hexatherm reads may not do
SAFE = {"no_network": True, "resolve_entities": False, "load_dtd": False, "huge_tree": False}


class _ShippedCopies(etree.Resolver):
    """Hands the schema compiler the shipped XML-Signature schema for its web address."""

    def resolve(self, url: str, pubid: str | None, context: Any) -> Any:
        if url == _XMLDSIG_URL:
            return self.resolve_filename(str(_XMLDSIG_FILE), context)
        return None


@functools.cache
def schema() -> etree.XMLSchema:
    """The compiled QIF 3.0 schema (``QIFDocument.xsd`` and every file it includes)."""
    parser = etree.XMLParser(**SAFE)
    parser.resolvers.add(_ShippedCopies())
    document = etree.parse(str(SCHEMA_DIR / "QIFApplications" / "QIFDocument.xsd"), parser)
    return etree.XMLSchema(document)


def local_name(element: Any) -> str:
    """An element's name without its namespace (``''`` for a comment or the like)."""
    tag = element.tag
    if not isinstance(tag, str):
        return ""
    return tag.rpartition("}")[2]


def check_element(element: Any, path: str | os.PathLike[str]) -> None:
    """Validate ``element`` (a global element of the QIF schema, in its tree) against the
    schema: InputError naming the file, the line and the element that breaks it.

    >>> from lxml import etree
    >>> units = etree.fromstring(
    ...     '<FileUnits xmlns="http://qifstandards.org/xsd/qif3"><PrimaryUnits>'
    ...     '<LinearUnit><SIUnitName>meter</SIUnitName><UnitName>inch</UnitName>'
    ...     '<UnitConversion><Factor>-1</Factor></UnitConversion></LinearUnit>'
    ...     '</PrimaryUnits></FileUnits>')
    >>> try:
    ...     check_element(units, "a.qif")
    ... except InputError as error:
    ...     print(error)  # doctest: +ELLIPSIS
    a.qif:1: field 'Factor': breaks the QIF 3 schema: ... The value '-1' must be greater than '0'.
    """
    checker = schema()
    if checker.validate(element):
        return
    error = checker.error_log.last_error
    raise InputError(
        f"breaks the QIF 3 schema: {_schema_message(error.message)}",
        path=path,
        line=error.line or element.sourceline,
        field=_element_of(error.message) or local_name(element),
    )


def check_document(path: str | os.PathLike[str]) -> None:
    """Validate a whole QIF file (what hexatherm writes; slow for a large file: see the
    module's notes): InputError naming the file, the line and the element."""
    with open_bounded(path) as stream:
        try:
            tree = etree.parse(stream, etree.XMLParser(**SAFE))
        except etree.XMLSyntaxError as exc:
            raise _syntax_error(exc, path) from None
    refuse_dtd(tree.getroot(), path)
    check_element(tree.getroot(), path)


def refuse_dtd(root: Any, path: str | os.PathLike[str]) -> None:
    """InputError when the document of ``root`` declares a DTD (``<!DOCTYPE``)."""
    info = root.getroottree().docinfo
    if info.doctype or info.internalDTD is not None or info.externalDTD is not None:
        raise InputError(
            "declares a DTD (<!DOCTYPE ...>): QIF needs none, and hexatherm reads no "
            "entity or DTD (entity expansion, external entities)",
            path=path,
            line=1,
            field="DOCTYPE",
        )


def iter_elements(
    path: str | os.PathLike[str], *, limit: int = MAX_MEASUREMENT_BYTES
) -> Iterator[tuple[str, Any]]:
    """``(event, element)`` pairs (``"start"``, ``"end"``) of a file parsed safely in a
    stream (see the module's notes); a DTD is refused at the first element, a syntax
    error (a truncated file, broken XML) in one line naming the file and the line."""
    with open_bounded(path, limit=limit) as stream:
        events = etree.iterparse(
            stream, events=("start", "end"), remove_comments=True, remove_pis=True, **SAFE
        )
        first = True
        try:
            for event, element in events:
                if first:
                    refuse_dtd(element, path)
                    first = False
                yield event, element
        except etree.XMLSyntaxError as exc:
            raise _syntax_error(exc, path) from None


def _syntax_error(exc: Any, path: str | os.PathLike[str]) -> InputError:
    message = str(exc.msg if getattr(exc, "msg", None) else exc)
    message = message.split(" (line ")[0].split(", line ")[0]
    message = message.replace(", use XML_PARSE_HUGE option", "")  # lxml's, not ours
    if "Document is empty" in message or "Start tag expected" in message:
        message = "not XML (no element found)"
    elif "Premature end of data" in message or "EndTag" in message or "end of data" in message:
        message = f"the XML ends early (a file cut short?): {message}"
    else:
        message = f"not well-formed XML: {message}"
    line = exc.lineno if getattr(exc, "lineno", None) else None
    return InputError(message, path=path, line=line)


def _element_of(message: str) -> str | None:
    """``Diameter`` of ``Element '{ns}Diameter': ...``."""
    if message.startswith("Element '"):
        name = message[len("Element '") :].split("'", 1)[0]
        return name.rpartition("}")[2]
    return None


def _schema_message(message: str) -> str:
    """libxml2's message without the element's namespace (the field names the element)."""
    return message.replace("{" + QIF_NS + "}", "").strip()
