"""Times written at once (``seconds_to_iso_texts``) are the texts ``datetime`` writes."""

from __future__ import annotations

import numpy as np

from hexatherm.io.records import seconds_to_iso, seconds_to_iso_fields, seconds_to_iso_texts


def test_the_texts_of_many_times_are_datetimes_own() -> None:
    # second method: datetime.fromtimestamp value by value; times on and about half
    # microseconds (where the rounding to even decides), whole seconds, the span's ends
    rng = np.random.default_rng(11)
    halves = np.round(rng.uniform(1e9, 2e9, 20000) * 2e6) / 2e6
    values = np.concatenate(
        [
            rng.uniform(0, 2e9, 20000),
            1.7e9 + np.arange(-3000, 3000) * 0.5e-6,
            halves,
            np.nextafter(halves, 0),
            np.nextafter(halves, np.inf),
            np.round(rng.uniform(1e9, 2e9, 1000)),
            [0.0, 0.0000005, 0.9999995, 1.9999996, 253402300799.0],
        ]
    )
    assert seconds_to_iso_texts(values) == [seconds_to_iso(v) for v in values.tolist()]


def test_times_outside_1970_to_9999_are_written_one_by_one() -> None:
    values = np.array([-0.25, 1577836810.25, -86400.0 * 365])
    assert seconds_to_iso_texts(values) == [seconds_to_iso(v) for v in values.tolist()]


def test_the_fields_of_many_times_are_datetimes_own_texts() -> None:
    # second method: datetime value by value; dates over the whole span (leap years,
    # 1900-like centuries, 2000, month ends), times on and about half microseconds, a
    # session's few days (each day's date once) and a span of years (a date per time)
    rng = np.random.default_rng(12)
    halves = np.round(rng.uniform(1.7e9, 1.7e9 + 3 * 86400, 20000) * 2e6) / 2e6
    days = np.arange(0, 2932897, 997) * 86400.0
    spans = [
        rng.uniform(0, 253402300799.0, 20000),
        np.concatenate([halves, np.nextafter(halves, 0), np.nextafter(halves, np.inf)]),
        np.concatenate([days, days - 1e-6, days + 0.9999995]).clip(0, 253402300799.0),
        np.array([0.0, 951782400.0, 951868799.9999995, 4107542400.0, 253402300799.0]),
        np.zeros(0),
    ]
    for values in spans:
        fields = seconds_to_iso_fields(values)
        assert fields is not None and fields.shape == (values.size, 26)
        texts = [bytes(row).decode("ascii") for row in fields]
        assert texts == [seconds_to_iso(v) for v in values.tolist()]
    assert seconds_to_iso_fields(np.array([1.7e9, -0.5])) is None
    assert seconds_to_iso_fields(np.array([1.7e9, np.nan])) is None
