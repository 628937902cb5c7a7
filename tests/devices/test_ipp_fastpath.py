"""The I++ line readers' fast path (one regular expression for the calls with numbers
that a campaign exchanges by the thousand) reads every line as the tokenizer and its
parser do: the same values, of the same types, or the same error with the same message,
on many generated lines and on their mutations (a character dropped, added, doubled)."""

from __future__ import annotations

import random

import pytest

from hexatherm.devices.ipp import parse_command, parse_data, parse_response
from hexatherm.devices.ipp.protocol import (
    _FAST_COMMAND,
    _as_text,
    _command_call,
    _fast_calls,
    _parse_data,
    _split_tag,
)
from hexatherm.errors import IppProtocolError

NOISE = '(),. \t"eE+-0123456789XYZ_.a#!&%'


def number(rng: random.Random) -> str:
    sign = rng.choice(["", "", "+", "-"])
    whole = str(rng.randrange(10 ** rng.randint(1, 6)))
    body = rng.choice(
        [whole, f"{whole}.", f"{whole}.{rng.randrange(1000)}", f".{rng.randrange(1, 10**5)}"]
    )
    if rng.random() < 0.3:
        body += rng.choice("eE") + rng.choice(["", "+", "-"]) + str(rng.randrange(10**3))
    if rng.random() < 0.1:
        body += str(rng.randrange(10))  # a 4-digit exponent, or a longer number
    return sign + body


def name(rng: random.Random) -> str:
    part = lambda: rng.choice(["X", "Y", "Z", "IJK", "ER", "Q", "Tool", "PtMeasPar", "Sp33d"])  # noqa: E731
    return ".".join(part() for _ in range(rng.choice([1, 1, 1, 2, 3])))


def space(rng: random.Random) -> str:
    return rng.choice(["", "", "", " ", "  ", "\t", " \t"])


def item(rng: random.Random, depth: int = 0) -> str:
    kind = rng.random()
    if kind < 0.7 or depth > 1:
        args = [number(rng) for _ in range(rng.choice([0, 1, 1, 1, 3]))]
        inner = ",".join(space(rng) + a + space(rng) for a in args)
        return f"{name(rng)}{space(rng)}({inner})"
    if kind < 0.8:
        return f'"{rng.choice(["Probe1", "F1", "", "a b"])}"'
    if kind < 0.87:
        return rng.choice(["Switch", "PartCsy", "E0553"])
    if kind < 0.93:
        return number(rng)
    return f"{name(rng)}({', '.join(item(rng, depth + 1) for _ in range(rng.randint(0, 3)))})"


def line(rng: random.Random) -> str:
    text = (space(rng) + "," + space(rng)).join(item(rng) for _ in range(rng.choice([1, 1, 2, 4])))
    return space(rng) + text + space(rng)


def mutate(rng: random.Random, text: str) -> str:
    for _ in range(rng.choice([1, 1, 2])):
        k = rng.randrange(len(text) + 1)
        how = rng.random()
        if how < 0.4 and text:
            text = text[:k] + text[k + 1 :]
        elif how < 0.8:
            text = text[:k] + rng.choice(NOISE) + text[k:]
        else:
            text = text[:k] + text[k:][:3] + text[k:]
    return text


def outcome(read, text: str) -> str:  # type: ignore[no-untyped-def]
    """What a reader makes of a line: its repr (Word, str and float apart) or its error."""
    try:
        return "ok " + repr(read(text))
    except IppProtocolError as error:
        return f"error {error}"


def lines(seed: int, n: int) -> list[str]:
    rng = random.Random(seed)
    out = []
    for _ in range(n):
        text = line(rng)
        out.append(text)
        out.append(mutate(rng, text))
    return out


@pytest.mark.parametrize("seed", range(4))
def test_data_lines_read_the_same_by_both_paths(seed: int) -> None:
    texts = lines(seed, 2500)
    fast = 0
    for text in texts:
        assert outcome(parse_data, text) == outcome(_parse_data, text), text
        fast += _fast_calls(text) is not None
    # both paths were taken, each many times
    assert 0.3 * len(texts) < fast < 0.8 * len(texts)


def general_command(rest: str):  # type: ignore[no-untyped-def]
    """``parse_command``'s call by the general parser alone."""
    return _command_call(_split_tag(_as_text(f"00042 {rest}"))[1])


@pytest.mark.parametrize("seed", range(4))
def test_command_lines_read_the_same_by_both_paths(seed: int) -> None:
    rng = random.Random(100 + seed)
    methods = ["GoTo", "PtMeas", "StartSession", "Get", "SetProp", "Tool.Goto", "ChangeTool"]
    fast = 0
    for text in lines(seed, 2500):
        for rest in (f"{rng.choice(methods)}{space(rng)}({text}){space(rng)}", text):
            if rng.random() < 0.2:
                rest = mutate(rng, rest)
            fast += _FAST_COMMAND.fullmatch(rest) is not None and "\t" not in rest
            got = outcome(lambda r: parse_command(f"00042 {r}")[1], rest)
            assert got == outcome(general_command, rest), rest
    assert fast > 100  # the fast path was taken
    # the empty call, the calls of a report request and of a move
    assert parse_command("00001 StartSession()")[1] == _command_call("StartSession()")
    for rest in ("OnPtMeasReport(X(), Y(), Z(), IJK())", "GoTo(X(1.5), Y(-2), Z(3e2))"):
        assert parse_command(f"00001 {rest}")[1] == _command_call(rest)


def test_illegal_characters_are_found_as_before() -> None:
    rng = random.Random(7)
    for _ in range(3000):
        text = "".join(
            chr(rng.choice([rng.randrange(32, 127)] * 20 + [rng.randrange(256)])) for _ in range(12)
        )
        bad = [c for c in text if not 32 <= ord(c) <= 126]
        if bad:
            with pytest.raises(IppProtocolError) as info:
                _as_text(text)
            assert str(info.value) == f"illegal character {bad[0]!r} (only ASCII 32..126 allowed)"
        else:
            assert _as_text(text + "\r\n") == text


def test_a_report_line_reads_whole() -> None:
    response = parse_response(b"00180 # X(75.0), Y(50), Z(4.0E+01), IJK(-1, 0, 0)")
    assert response.data == _parse_data("X(75.0), Y(50), Z(4.0E+01), IJK(-1, 0, 0)")
    assert [type(a) for call in response.data for a in call.args] == [float] * 6  # type: ignore[union-attr]
