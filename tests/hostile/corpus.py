"""The hostile cases: valid inputs of :mod:`tests.hostile.bases`, corrupted every way we know.

Each :class:`Case` writes its input into an empty folder at test time (nothing large is
committed; the biggest input is a 4 MiB zip bomb member, compressed to a few kB). Text
tables get line- and byte-level corruptions (:data:`TEXT_MUTATIONS`), bags and their
folders binary ones, zips hostile members, building models broken geometry; a few cases
give hostile option values to a valid input. :data:`CASES` lists them all, by id
``<base>-<corruption>``.
"""

from __future__ import annotations

import shutil
import stat
import zipfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np

from tests.hostile.bases import BASES, Base

__all__ = ["CASES", "TEXT_MUTATIONS", "Case"]

Mutation = Callable[[Base, bytes], bytes | None]
"""``(base, valid bytes) -> hostile bytes``, or None when it does not apply to the base."""

_LONG: Final = 1_000_000
"""Length of the very long line or cell: 1 MB, bounded."""


@dataclass(frozen=True)
class Case:
    """One hostile input and how it is given to loceval.

    Attributes:
        id: ``<base>-<corruption>``.
        base: the valid input it was made from (role, selector).
        build: writes the input into an empty folder; returns its path.
        args: more command-line options (option cases).
        options: the same options for the API's evaluation request.
        valid: the input is valid: the commands must succeed.
    """

    id: str
    base: Base
    build: Callable[[Path], Path]
    args: tuple[str, ...] = ()
    options: Mapping[str, Any] = field(default_factory=dict)
    valid: bool = False


# --- text tables -------------------------------------------------------------------------


def _split(base: Base, data: bytes) -> tuple[list[str], list[list[str]]]:
    """Return the header lines and the data rows (cells) of a valid text table."""
    lines = data.decode().replace("\r\n", "\n").rstrip("\n").split("\n")
    header, body = lines[: base.header_lines], lines[base.header_lines :]
    return header, [row.split(base.delimiter) for row in body]


def _join(base: Base, header: list[str], rows: list[list[str]]) -> bytes:
    sep = base.delimiter or " "
    return ("\n".join([*header, *(sep.join(r) for r in rows)]) + "\n").encode()


def _cells(edit: Callable[[Base, list[str], list[list[str]]], bool | None]) -> Mutation:
    """Make a mutation from an in-place edit of the header and rows (False: not applicable)."""

    def mutate(base: Base, data: bytes) -> bytes | None:
        header, rows = _split(base, data)
        if edit(base, header, rows) is False:
            return None
        return _join(base, header, rows)

    return mutate


def _set(column: str, value: str) -> Mutation:
    """Set one cell (``value``/``time``/``name`` column) of the fourth data row."""

    def edit(base: Base, _header: list[str], rows: list[list[str]]) -> bool:
        index = getattr(base, f"{column}_column")
        if index is None:
            return False
        rows[3][index] = value
        return True

    return _cells(edit)


def _header_only(base: Base, data: bytes) -> bytes | None:
    header, _ = _split(base, data)
    return ("\n".join(header) + "\n").encode() if header else None


def _rows_only(count: int) -> Mutation:
    def edit(_base: Base, _header: list[str], rows: list[list[str]]) -> None:
        del rows[count:]

    return _cells(edit)


def _swap(_base: Base, _header: list[str], rows: list[list[str]]) -> None:
    rows[2], rows[3] = rows[3], rows[2]


def _duplicate(_base: Base, _header: list[str], rows: list[list[str]]) -> None:
    rows.insert(3, list(rows[3]))


def _same_time(base: Base, _header: list[str], rows: list[list[str]]) -> bool:
    if base.time_column is None:
        return False
    for row in rows:
        row[base.time_column] = rows[0][base.time_column]
    return True


def _drop_column(_base: Base, _header: list[str], rows: list[list[str]]) -> None:
    for row in rows:
        row.pop()


def _extra_column(_base: Base, _header: list[str], rows: list[list[str]]) -> None:
    for row in rows:
        row.append("1")


def _ragged(_base: Base, _header: list[str], rows: list[list[str]]) -> None:
    rows[2].pop()
    rows[4] += ["1", "2"]
    rows[-1] = rows[-1][:1]


def _wide_row(_base: Base, _header: list[str], rows: list[list[str]]) -> None:
    rows[3] += ["0"] * 20_000


def _semicolons(base: Base, header: list[str], rows: list[list[str]]) -> bool:
    if base.delimiter != ",":
        return False
    header[:] = [h.replace(",", ";") for h in header]
    rows[:] = [[";".join(r)] for r in rows]
    return True


def _ansi_name(base: Base, header: list[str], rows: list[list[str]]) -> None:
    evil = "\x1b[31mRED\x1b[0m\x07\x08"
    if base.name_column is not None:
        rows[3][base.name_column] = evil
    elif header:
        header[-1] += evil
    else:
        rows.insert(0, [f"# {evil}"])


def _truncate(where: Callable[[bytes], int]) -> Mutation:
    return lambda _base, data: data[: where(data)]


def _encode(transform: Callable[[bytes], bytes]) -> Mutation:
    return lambda _base, data: transform(data)


def _long_comment(base: Base, data: bytes) -> bytes | None:
    header, rows = _split(base, data)
    header.append("#" + "x" * _LONG)
    return _join(base, header, rows)


def _non_utf8(_base: Base, data: bytes) -> bytes:
    first, _, rest = data.partition(b"\n")
    return first + b"\xff\xc3\x28\xfe" + b"\n" + rest


def _garbage(size: int, *, printable: bool = False) -> Mutation:
    def mutate(_base: Base, _data: bytes) -> bytes:
        rng = np.random.default_rng(size)
        if printable:
            return bytes(rng.integers(32, 127, size, dtype=np.uint8)).replace(b"~", b"\n")
        return bytes(rng.integers(0, 256, size, dtype=np.uint8))

    return mutate


TEXT_MUTATIONS: Final[dict[str, Mutation]] = {
    "empty": lambda _b, _d: b"",
    "blank": lambda _b, _d: b"  \n\t \r\n\n   ",
    "header-only": _header_only,
    "one-row": _rows_only(1),
    "two-rows": _rows_only(2),
    "trunc-1": _truncate(lambda _d: 1),
    "trunc-first-line": _truncate(lambda d: d.index(b"\n") // 2),
    "trunc-half": _truncate(lambda d: len(d) // 2),
    "trunc-tail": _truncate(lambda d: len(d) - 7),
    "garbage": _garbage(4096),
    "garbage-text": _garbage(4096, printable=True),
    "nul-bytes": _encode(lambda d: d[: len(d) // 2] + b"\x00" * 16 + d[len(d) // 2 :]),
    "value-nan": _set("value", "nan"),
    "value-inf": _set("value", "inf"),
    "value-1e308": _set("value", "1e308"),
    "value-neg0": _set("value", "-0"),
    "value-hugeint": _set("value", "9" * 40),
    "value-empty": _set("value", ""),
    "value-text": _set("value", "abc"),
    "time-nan": _set("time", "nan"),
    "time-1e308": _set("time", "1e308"),
    "time-hugeint": _set("time", "9" * 40),
    "time-negative": _set("time", "-5"),
    "swapped-rows": _cells(_swap),
    "duplicate-row": _cells(_duplicate),
    "same-time": _cells(_same_time),
    "drop-column": _cells(_drop_column),
    "extra-column": _cells(_extra_column),
    "ragged": _cells(_ragged),
    "wide-row": _cells(_wide_row),
    "semicolons": _cells(_semicolons),
    "bom": _encode(lambda d: b"\xef\xbb\xbf" + d),
    "utf16": _encode(lambda d: d.decode().encode("utf-16")),
    "crlf": _encode(lambda d: d.replace(b"\r\n", b"\n").replace(b"\n", b"\r\n")),
    "cr-only": _encode(lambda d: d.replace(b"\r\n", b"\n").replace(b"\n", b"\r")),
    "long-cell": _set("value", "1" * _LONG),
    "long-comment": _long_comment,
    "non-utf8": _non_utf8,
    "ansi-name": _cells(_ansi_name),
}
"""Every corruption of a text table, by name."""


def _applies(base: Base, name: str) -> bool:
    """Whether a text mutation applies to a base (it has the header or column it edits)."""
    if name == "header-only":
        return base.header_lines > 0
    if name.startswith("time-") or name == "same-time":
        return base.time_column is not None
    if name == "semicolons":
        return base.delimiter == ","
    return True


def _text_case(base: Base, name: str, mutate: Mutation) -> Case:
    def build(into: Path) -> Path:
        path = base.write(into)
        hostile = mutate(base, path.read_bytes())
        assert hostile is not None
        path.write_bytes(hostile)
        return path

    return Case(f"{base.name}-{name}", base, build)


def _wrong_extension(base: Base) -> Case:
    def build(into: Path) -> Path:
        path = base.write(into)
        return path.rename(path.with_suffix(".mcap"))

    return Case(f"{base.name}-wrong-ext", base, build)


# --- bags ------------------------------------------------------------------------------


def _bytes_case(base: Base, name: str, mutate: Callable[[bytes], bytes]) -> Case:
    """Corrupt a bag file, or the storage file inside a bag folder."""

    def build(into: Path) -> Path:
        path = base.write(into)
        target = path if path.is_file() else _storage(path)
        target.write_bytes(mutate(target.read_bytes()))
        return path

    return Case(f"{base.name}-{name}", base, build)


def _storage(folder: Path) -> Path:
    return next(p for p in sorted(folder.iterdir()) if p.suffix in {".db3", ".mcap"})


def _folder_case(base: Base, name: str, edit: Callable[[Path], None]) -> Case:
    def build(into: Path) -> Path:
        path = base.write(into)
        edit(path)
        return path

    return Case(f"{base.name}-{name}", base, build)


def _metadata(text: str) -> Callable[[Path], None]:
    return lambda folder: (folder / "metadata.yaml").write_text(text)


def _escaping_metadata(folder: Path) -> None:
    meta = folder / "metadata.yaml"
    name = _storage(folder).name
    meta.write_text(meta.read_text().replace(f"- {name}", "- ../../../../etc/passwd"))


BAG_MUTATIONS: Final[dict[str, Callable[[bytes], bytes]]] = {
    "empty": lambda _d: b"",
    "magic-only": lambda d: d[:16],
    "trunc-64": lambda d: d[:64],
    "trunc-half": lambda d: d[: len(d) // 2],
    "trunc-tail": lambda d: d[:-100],
    "garbage": lambda d: _garbage(len(d))(BASES["tum"], d) or b"",
    "magic-garbage": lambda d: d[:16] + (_garbage(4096)(BASES["tum"], d) or b""),
    "zeroed-middle": lambda d: d[: len(d) // 3] + b"\x00" * (len(d) // 3) + d[2 * len(d) // 3 :],
}
"""Byte-level corruptions of a bag file (or a bag folder's storage file)."""

FOLDER_EDITS: Final[dict[str, Callable[[Path], None]]] = {
    "no-metadata": lambda folder: (folder / "metadata.yaml").unlink(),
    "empty-metadata": _metadata(""),
    "garbage-metadata": _metadata("\x00\x01 not: [yaml"),
    "list-metadata": _metadata("- 1\n- 2\n"),
    "no-storage": lambda folder: _storage(folder).unlink(),
    "escaping-metadata": _escaping_metadata,
    "extra-garbage-file": lambda folder: (folder / "junk.db3").write_bytes(b"\x00" * 64),
}
"""Edits of a ROS 2 bag folder."""


def _selector_case(base: Base, name: str, selector: str) -> Case:
    return Case(f"{base.name}-{name}", Base(**{**base.__dict__, "selector": selector}), base.write)


# --- zips ------------------------------------------------------------------------------


def _valid_members(into: Path) -> list[tuple[str, bytes]]:
    """The members of the valid zipped bag (folder ``unzipped/rec``), read back."""
    path = BASES["bagzip"].write(into)
    with zipfile.ZipFile(path) as archive:
        members = [(n, archive.read(n)) for n in archive.namelist()]
    path.unlink()
    shutil.rmtree(into / "unzipped")
    return members


def _zip_case(name: str, extra: Callable[[zipfile.ZipFile], None], *, bag: bool = True) -> Case:
    def build(into: Path) -> Path:
        members = _valid_members(into) if bag else []
        path = into / "rec.zip"
        with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
            for member, data in members:
                archive.writestr(member, data)
            extra(archive)
        return path

    return Case(f"zip-{name}", BASES["bagzip"], build)


def _symlink(archive: zipfile.ZipFile) -> None:
    info = zipfile.ZipInfo("rec/link.db3")
    info.create_system = 3
    info.external_attr = (stat.S_IFLNK | 0o777) << 16
    archive.writestr(info, "/etc/passwd")


def _encrypted(archive: zipfile.ZipFile) -> None:
    info = zipfile.ZipInfo("rec/secret.txt")
    archive.writestr(info, b"hidden")
    archive.infolist()[-1].flag_bits |= 0x1


def _nested(archive: zipfile.ZipFile) -> None:
    inner = Path(archive.filename or "x").with_name("inner.zip")
    with zipfile.ZipFile(inner, "w") as nested:
        nested.writestr("deeper.zip", b"PK\x05\x06" + b"\x00" * 18)
    archive.write(inner, "inner.zip")
    inner.unlink()


def _duplicate_member(archive: zipfile.ZipFile) -> None:
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        archive.writestr("rec/metadata.yaml", b"garbage: [")


def _many(archive: zipfile.ZipFile) -> None:
    for k in range(10_050):
        archive.writestr(f"rec/m{k}", b"")


ZIP_CASES: Final[list[Case]] = [
    _zip_case("dotdot", lambda z: z.writestr("../evil.txt", b"x")),
    _zip_case("dotdot-nested", lambda z: z.writestr("rec/../../evil.db3", b"x")),
    _zip_case("absolute", lambda z: z.writestr("/etc/evil.txt", b"x")),
    _zip_case("backslash", lambda z: z.writestr("..\\..\\evil.txt", b"x")),
    _zip_case("drive-letter", lambda z: z.writestr("C:/evil.txt", b"x")),
    _zip_case("symlink", _symlink),
    _zip_case("bomb", lambda z: z.writestr("rec/bomb.bin", b"\x00" * (4 << 20))),
    _zip_case("bomb-only", lambda z: z.writestr("bomb.bag", b"\x00" * (4 << 20)), bag=False),
    _zip_case("nested", _nested, bag=False),
    _zip_case("nested-with-bag", _nested),
    _zip_case("duplicate-member", _duplicate_member),
    _zip_case("encrypted", _encrypted),
    _zip_case("empty", lambda _z: None, bag=False),
    _zip_case("text-only", lambda z: z.writestr("notes.txt", b"hello\n"), bag=False),
    _zip_case(
        "garbage-bag", lambda z: z.writestr("x.bag", b"#ROSBAG V2.0\n" + b"\x01" * 99), bag=False
    ),
    _zip_case("two-bags", lambda z: z.writestr("other/metadata.yaml", b"x: 1\n")),
    _zip_case("ansi-member", lambda z: z.writestr("rec/\x1b[31mred\x1b[0m.txt", b"x")),
    _zip_case("dirs-only", lambda z: z.writestr("rec/", b""), bag=False),
    _zip_case("many-members", _many, bag=False),
]
"""Hostile zips (of a bag folder, or of nothing usable)."""


def _truncated_zip(fraction: float) -> Case:
    def build(into: Path) -> Path:
        path = BASES["bagzip"].write(into)
        data = path.read_bytes()
        path.write_bytes(data[: int(len(data) * fraction)])
        return path

    return Case(f"zip-trunc-{int(fraction * 100)}", BASES["bagzip"], build)


# --- building models -------------------------------------------------------------------


def _building(base: Base, name: str, suffix: str, content: Callable[[bytes], bytes]) -> Case:
    def build(into: Path) -> Path:
        path = base.write(into)
        data = path.read_bytes()
        path.unlink()
        target = path.with_suffix(suffix)
        target.write_bytes(content(data))
        return target

    return Case(f"{base.name}-{name}", base, build)


def _building_cases() -> list[Case]:
    obj, dxf = BASES["obj"], BASES["dxf"]
    noise = _garbage(2048)
    return [
        _building(obj, "empty", ".obj", lambda _d: b""),
        _building(obj, "garbage", ".obj", lambda d: noise(obj, d) or b""),
        _building(obj, "trunc-half", ".obj", lambda d: d[: len(d) // 2]),
        _building(obj, "nan-vertex", ".obj", lambda d: d.replace(b"v 0 0 0", b"v nan 0 0")),
        _building(obj, "huge-vertex", ".obj", lambda d: d.replace(b"v 0 0 0", b"v 1e308 0 0")),
        _building(obj, "faces-only", ".obj", lambda _d: b"f 1 2 3\nf 4 5 6\n"),
        _building(obj, "as-stl", ".stl", lambda d: noise(obj, d) or b""),
        _building(obj, "as-ply", ".ply", lambda _d: b"ply\nformat ascii 1.0\nelement vertex 9\n"),
        _building(obj, "as-glb", ".glb", lambda d: b"glTF" + (noise(obj, d) or b"")),
        _building(obj, "as-ifc", ".ifc", lambda _d: b"ISO-10303-21;\nHEADER;\nENDSEC;\n"),
        _building(obj, "garbage-ifc", ".ifc", lambda d: noise(obj, d) or b""),
        _building(dxf, "empty", ".dxf", lambda _d: b""),
        _building(dxf, "garbage", ".dxf", lambda d: noise(dxf, d) or b""),
        _building(dxf, "trunc-half", ".dxf", lambda d: d[: len(d) // 2]),
        _building(dxf, "obj-content", ".dxf", lambda _d: b"v 0 0 0\nf 1 1 1\n"),
    ]


# --- options ---------------------------------------------------------------------------


def _option_case(name: str, args: tuple[str, ...], options: Mapping[str, Any]) -> Case:
    base = BASES["tum"]
    return Case(f"option-{name}", base, base.write, args=args, options=options)


OPTION_CASES: Final[list[Case]] = [
    _option_case("site-1e308", ("--site", "1e308 0 0 0", "--formats", "paths.dxf"),
                 {"site": "1e308 0 0 0", "formats": ["paths.dxf"]}),
    _option_case("rpe-delta-tiny", ("--rpe-delta", "1e-300", "--rpe-unit", "s"),
                 {"rpe_delta": 1e-300, "rpe_unit": "s"}),
    _option_case("time-offset-huge", ("--time-offset", "1e308"), {"time_offset_s": 1e308}),
    _option_case("max-dt-huge", ("--associate", "nearest", "--max-dt", "1e308"),
                 {"association": "nearest", "max_dt_s": 1e308}),
    _option_case("thresholds-inf", ("--thresholds", "inf,1e308"),
                 {"thresholds_m": [1e308]}),
    _option_case("worst-huge", ("--worst", "9" * 30), {"worst": 10**30}),
    _option_case("offset-nan", ("--offset", "nan 0 0 0 0 0 1"), {"offset": "nan 0 0 0 0 0 1"}),
    _option_case("ansi-name-report", ("--name", "\x1b[31mred\x1b[0m", "--formats", "report.html"),
                 {"formats": ["report.html"]}),
]  # fmt: skip
"""Hostile option values with a valid TUM reference."""


# --- tiny files ----------------------------------------------------------------------

TINY: Final[dict[str, bytes]] = {
    "1c": b"\x1c",  # the ASCII separators: whitespace to Python's str.strip, not to bytes'
    "1d": b"\x1d",
    "1e": b"\x1e",
    "1f": b"\x1f",
    "nel": "\x85".encode(),  # U+0085 and U+2028: Unicode line breaks
    "ls": "\u2028".encode(),
    "nul": b"\x00",
    "ff": b"\xff",
    "hash": b"#",
    "comma": b",",
    "digit": b"7",
    "newline": b"\n",
    "1c-lines": b"\x1c\n\x1d\n\x1e\n",
}
"""One-byte and other tiny files, by name."""


def _tiny_case(base: Base, name: str, content: bytes) -> Case:
    def build(into: Path) -> Path:
        path = into / base.filename
        path.write_bytes(content)
        return path

    return Case(f"{base.name}-tiny-{name}", base, build)


def _tiny_cases() -> list[Case]:
    """Every tiny file under a TUM name; the separators under the other text and model names."""
    cases = [_tiny_case(BASES["tum"], name, content) for name, content in TINY.items()]
    for base in ("csv", "points", "anchors", "ranges", "obj", "dxf"):
        cases += [_tiny_case(BASES[base], name, TINY[name]) for name in ("1c", "1d", "1e")]
    return cases


# --- the list --------------------------------------------------------------------------


def _all_cases() -> list[Case]:
    cases = [Case(f"{b.name}-valid", b, b.write, valid=True) for b in BASES.values()]
    for base in BASES.values():
        if not base.text:
            continue
        cases += [
            _text_case(base, name, mutate)
            for name, mutate in TEXT_MUTATIONS.items()
            if _applies(base, name)
        ]
        cases.append(_wrong_extension(base))
    for name in ("bag1", "mcapfile", "db3file", "bagzip"):
        cases += [_bytes_case(BASES[name], m, f) for m, f in BAG_MUTATIONS.items()]
        cases.append(_wrong_extension(BASES[name]))
    for name in ("db3dir", "mcapdir"):
        cases += [_folder_case(BASES[name], e, f) for e, f in FOLDER_EDITS.items()]
        cases += [_bytes_case(BASES[name], m, BAG_MUTATIONS[m]) for m in ("empty", "trunc-half")]
    for name in ("bag1", "mcapdir"):
        cases.append(_selector_case(BASES[name], "unknown-topic", "@/nope"))
        cases.append(_selector_case(BASES[name], "unknown-tf", "@tf:nowhere:nothing"))
        cases.append(_selector_case(BASES[name], "string-topic", "@/chatter"))
        cases.append(_selector_case(BASES[name], "ansi-selector", "@/\x1b[31mred"))
    cases += ZIP_CASES + [_truncated_zip(f) for f in (0.1, 0.5, 0.95)]
    cases += _building_cases()
    cases += _tiny_cases()
    cases += OPTION_CASES
    ids = [case.id for case in cases]
    assert len(ids) == len(set(ids)), "case ids must be unique"
    return cases


CASES: Final[list[Case]] = _all_cases()
"""Every hostile case (and one valid case per base), in a stable order."""
