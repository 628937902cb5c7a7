"""Writers of what CMM software exports, for the tests: a session's ball centres as a
folder of Zeiss Calypso table files (one run per step, written the way Calypso writes
them: tab-separated, CRLF, seven decimals, Latin-1, the sphere's X, Y, Z and diameter
as characteristics of their own beside other features), and as a foreign table through
a column map (``;``, decimal comma, any unit). Never part of hexatherm: the readers are
held to files these write, and to the public layout they follow."""

from __future__ import annotations

from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from hexatherm.io.records import Records

#: the columns of a Calypso ``_chr.txt`` (Calypso 6.x, with ``unit``), as public files show
CHR_COLUMNS = (
    "planid partnb id type idsymbol actual nominal uppertol lowertol deviation exceed "
    "warningLimitCF featureid featuresigma comment link linkmode mmc useruppertol "
    "userlowertol fftphi fftphiunit zoneroundnessangle groupname groupname2 datumAid "
    "datumBid datumCid natuppertolid natlowertolid decimalplaces featurePosX featurePosY "
    "featurePosZ unit group1 group2 group3 group4 group5 group6 group7 group8 group9 group10"
).split()
#: the first fields of a Calypso ``_hdr.txt`` (its header line), as public tools list them
HDR_COLUMNS = (
    "planid partnb filename operid date dateshort time tmeid devicegroup dmesn "
    "controllertyp dmeswi dmeswv pointCloudFile measRun actpgnr nrpgs lengthunit partid"
).split()

INCH_MM = 25.4


def step_times(records: Records, labels: Sequence[str]) -> dict[str, float]:
    """Each step's time as one run has it: the mean of its balls' times, whole seconds."""
    return {
        label: float(np.round(records.time_s[records.label == label].mean())) for label in labels
    }


def _chr_row(values: dict[str, str]) -> str:
    return "\t".join(values.get(c, "") for c in CHR_COLUMNS)


def write_calypso(
    records: Records,
    labels: Sequence[str],
    folder: Path,
    features: dict[str, str],
    *,
    step_in_header: bool = True,
    unit: str = "mm",
    date_layout: str = "%b %d, %Y",
) -> None:
    """One run per step of ``labels`` in ``folder``: ``run<k>_chr/_hdr/_fet.txt``.

    ``features``: ball -> Calypso feature name. The run's time is the step's
    (:func:`step_times`), in the header's ``date`` and ``time``; with
    ``step_in_header`` the step label is the run's ``partnb`` (the operator typed it).
    """
    folder.mkdir(parents=True, exist_ok=True)
    times = step_times(records, labels)
    scale = INCH_MM if unit == "inch" else 1.0
    for k, label in enumerate(labels):
        stamp = datetime.fromtimestamp(times[label], tz=UTC)
        run = f"run{k + 1:03d}"
        partnb = label if step_in_header else str(k + 1)
        hdr = {
            "planid": "hexapod 3 Kugeln",
            "partnb": partnb,
            "filename": f"{run}.txt",
            "operid": "Müller",
            "date": stamp.strftime(date_layout).replace(" 0", " "),
            "dateshort": f"{stamp.year}-{stamp.month}-{stamp.day}",
            "time": f"{stamp.hour}:{stamp.minute:02d}:{stamp.second:02d}",
            "lengthunit": unit,
        }
        lines = ["\t".join(HDR_COLUMNS), "\t".join(hdr.get(c, "") for c in HDR_COLUMNS)]
        _write(folder / f"{run}_hdr.txt", lines)
        rows = ["\t".join(CHR_COLUMNS) + "\t"]
        common = {"planid": hdr["planid"], "partnb": partnb, "unit": unit, "decimalplaces": "4"}
        # an alignment plane first: a characteristic that is no sphere
        rows.append(
            _chr_row(
                {
                    **common,
                    "id": "Ebenheit Auflage",
                    "type": "Ebenheit",
                    "idsymbol": "gdtFlat",
                    "actual": "0.0012000",
                    "featureid": "Ebene_Auflage",
                }
            )
        )
        here = records.label == label
        for ball, xyz in zip(records.ball[here], records.xyz_mm[here], strict=True):
            feature = features[str(ball)]
            diameter = (
                25.4
                if records.diameter_mm is None
                else float(records.diameter_mm[here][records.ball[here] == ball][0])
            )
            cells = {**common, "featureid": feature, "groupname": "Kugeln"}
            for axis, value in zip("XYZ", xyz, strict=True):
                rows.append(
                    _chr_row(
                        {
                            **cells,
                            "id": f"{feature}_{axis}",
                            "type": f"{axis}-Wert",
                            "idsymbol": f"{axis.lower()}Value",
                            "actual": f"{value / scale:.7f}",
                            "nominal": f"{value / scale:.3f}",
                        }
                    )
                )
            rows.append(
                _chr_row(
                    {
                        **cells,
                        "id": f"{feature}_D",
                        "type": "Durchmesser Ø",
                        "idsymbol": "diameter",
                        "actual": f"{diameter / scale:.7f}",
                    }
                )
            )
        _write(folder / f"{run}_chr.txt", rows)
        _write(
            folder / f"{run}_fet.txt", ["planid\tpartnb\tid\ttype", f"{hdr['planid']}\t{partnb}"]
        )


def write_foreign_table(
    records: Records,
    path: Path,
    *,
    unit: str = "inch",
    decimals: int = 8,
) -> None:
    """A table as a spreadsheet exports it: ``;``-separated, decimal comma, the
    feature's name ``<step>-<ball>`` in one column, date and time in two, ``unit``."""
    scale = INCH_MM if unit == "inch" else 1.0
    lines = ["Merkmal;X;Y;Z;Durchmesser;Datum;Uhrzeit"]
    for label, ball, xyz, t in zip(
        records.label, records.ball, records.xyz_mm, records.time_s, strict=True
    ):
        stamp = datetime.fromtimestamp(float(t), tz=UTC)
        numbers = [f"{v / scale:.{decimals}f}".replace(".", ",") for v in (*xyz, 25.4)]
        lines.append(f"{label}.{ball};{';'.join(numbers)};{stamp:%d.%m.%Y};{stamp:%H:%M:%S}")
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode("utf-8"))


def _write(path: Path, lines: list[str]) -> None:
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode("latin-1"))
