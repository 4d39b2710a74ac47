"""The vectorised table parser gives np.loadtxt's values bit for bit, or declines."""

from __future__ import annotations

import io

import numpy as np
import pytest

from loceval.readers import _plain
from loceval.readers._plain import parse_plain

TRICKY = [
    "1700000000.005000114",
    "-0",
    "+0.5",
    ".5",
    "-.5",
    "5.",
    "00012.50",
    "1e5",
    "1E-5",
    "-1.5e+22",
    "1.403715529112143517e+09",
    "-2.730000000000000135e-02",
    "0.000753986",
]


def _loadtxt(text: str, delimiter: str | None) -> np.ndarray:
    return np.loadtxt(io.StringIO(text), delimiter=delimiter, ndmin=2)


@pytest.mark.parametrize("delimiter", [None, ","])
def test_tricky_numbers_match_loadtxt_bit_for_bit(delimiter: str | None) -> None:
    sep = " " if delimiter is None else delimiter
    text = "\n".join(sep.join([t, "1.25", t]) for t in TRICKY) + "\n"
    parsed = parse_plain(text.encode(), delimiter=delimiter)
    assert parsed is not None
    values, lines, _ = parsed
    expected = _loadtxt(text, delimiter)
    assert values.shape == expected.shape
    assert (values.view(np.int64) == expected.view(np.int64)).all()  # -0.0 included
    assert lines.tolist() == list(range(len(TRICKY)))


def test_every_digit_count_in_one_table_matches_loadtxt() -> None:
    """Numbers of 1 to 19 digits side by side (read in one to five lanes) keep their values."""
    rng = np.random.default_rng(5)
    cells = []
    for digits in range(1, 20):
        for _ in range(40):
            text = "".join(rng.choice(list("0123456789"), size=digits))
            point = int(rng.integers(0, digits + 1))
            sign = rng.choice(["", "-", "+"])
            cells.append(f"{sign}{text[:point]}.{text[point:]}" if point < digits else sign + text)
    order = rng.permutation(len(cells))
    rows = [" ".join(cells[k] for k in order[i : i + 4]) for i in range(0, len(order), 4)]
    text = "\n".join(rows) + "\n"
    parsed = parse_plain(text.encode(), delimiter=None)
    assert parsed is not None
    expected = _loadtxt(text, None)
    assert (parsed[0].view(np.int64) == expected.view(np.int64)).all()


def test_random_stamps_across_chunks_match_loadtxt(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_plain, "_CHUNK_BYTES", 97)
    rng = np.random.default_rng(3)
    rows = np.column_stack([1.7e9 + np.cumsum(rng.random(500)), rng.normal(size=(500, 7))])
    buffer = io.StringIO()
    np.savetxt(buffer, rows, fmt="%.9f")
    text = buffer.getvalue().replace("\n", "\r\n", 40)
    parsed = parse_plain(text.encode(), delimiter=None)
    assert parsed is not None
    expected = np.loadtxt(io.StringIO(text))
    assert (parsed[0].view(np.int64) == expected.view(np.int64)).all()


def test_blank_lines_keep_their_line_numbers() -> None:
    parsed = parse_plain(b"1 2\n\n   \n3 4\n", delimiter=None)
    assert parsed is not None
    assert parsed[1].tolist() == [0, 3]


def test_exact_integer_first_column() -> None:
    parsed = parse_plain(b"1403715524907143168,1.5\n-7,2\n", delimiter=",", int_first=True)
    assert parsed is not None
    assert parsed[2] is not None
    assert parsed[2].tolist() == [1403715524907143168, -7]
    floats = parse_plain(b"1.0,1.5\n2,2\n", delimiter=",", int_first=True)
    assert floats is not None
    assert floats[2] is None


@pytest.mark.parametrize(
    ("text", "delimiter"),
    [
        (b"1 nan\n", None),  # letters
        (b"1 2\n3\n", None),  # ragged rows
        (b"1,,2\n", ","),  # empty cell
        (b"1 2 # note\n", None),  # comment
        (b"1-2 3\n", None),  # sign inside a number
        (b"1.2.3 4\n", None),  # two points
        (b"1 2\r3 4\n", None),  # lone carriage return
        (b"1e400 2\n", None),  # exponent out of the exact range
        (b"123456789012345678901 2\n", None),  # more than 19 digits
        (b"1\x0c2\n", None),  # form feed
        (b"1,2 3\n", ","),  # two cells in one field
        (b"9007199254740993.0 1\n", None),  # exactly halfway between two doubles
    ],
)
def test_declines_what_it_does_not_read(text: bytes, delimiter: str | None) -> None:
    assert parse_plain(text, delimiter=delimiter) is None


def test_threaded_chunks_give_the_serial_result(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_plain, "_CHUNK_BYTES", 64)
    monkeypatch.setattr(_plain, "_THREADS_FROM", 4)
    monkeypatch.setattr(_plain.os, "cpu_count", lambda: 2)
    lines = [f"{1_700_000_000_000 + 7 * k},{k * 0.25}" for k in range(300)]
    lines.insert(150, "")  # a blank line halfway: later rows keep their line numbers
    data = ("\n".join(lines) + "\n").encode()
    threaded = parse_plain(data, delimiter=",", int_first=True)
    monkeypatch.setattr(_plain, "_THREADS_FROM", 10**9)
    serial = parse_plain(data, delimiter=",", int_first=True)
    assert threaded is not None
    assert serial is not None
    assert (threaded[0].view(np.int64) == serial[0].view(np.int64)).all()
    assert threaded[1].tolist() == serial[1].tolist() == [*range(150), *range(151, 301)]
    assert threaded[2] is not None
    assert serial[2] is not None
    assert threaded[2].tolist() == serial[2].tolist()


def test_threaded_chunks_decline_a_bad_late_line(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_plain, "_CHUNK_BYTES", 64)
    monkeypatch.setattr(_plain, "_THREADS_FROM", 4)
    monkeypatch.setattr(_plain.os, "cpu_count", lambda: 2)
    data = "".join(f"{k} {k}.5\n" for k in range(300)).encode() + b"7 nan\n"
    assert parse_plain(data, delimiter=None) is None
