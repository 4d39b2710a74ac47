"""The .3dm's ATE runs spliced in as records: the model rhino3dm would write with every run.

``exporters.cad.rhino_bulk`` lets rhino3dm write one placeholder per colour bin and lays out
every run's object record itself; rhino3dm adding every run (``_model(bulk=False)``) is the
slow path it replaces. Both files are read back with rhino3dm and compared object by object.
"""

from __future__ import annotations

import struct
import uuid
import zlib

import numpy as np
import pytest

from exporters.cad.placement import parse_site, place_evaluation
from exporters.cad.records import constant, fill_crc32, interleave, rows
from exporters.options import ExportOptions
from loceval.evaluation import EvaluationResult
from tests.exporters.conftest import with_reference_loss

rhino3dm = pytest.importorskip("rhino3dm")
from exporters.cad import rhino, rhino_bulk  # noqa: E402  (after the importorskip)

SITE = "512340.25 5403210.5 112.3 37.5"


def described(model: object) -> list[tuple[object, ...]]:
    """Return what each object of a model shows, in the model's order (its id aside)."""
    out = []
    for obj in model.Objects:
        attributes, geometry = obj.Attributes, obj.Geometry
        shape = geometry.Text if isinstance(geometry, rhino3dm.TextDot) else geometry.Encode()
        out.append(
            (
                attributes.Name,
                attributes.LayerIndex,
                tuple(attributes.ObjectColor),
                attributes.ColorSource,
                sorted(attributes.GetUserStrings()),
                type(geometry).__name__,
                shape if isinstance(shape, str) else shape["data"],
                sorted(geometry.GetUserStrings()),
            )
        )
    return out


def layers(model: object) -> list[tuple[object, ...]]:
    """Return each layer's full path, colour and visibility."""
    return [(layer.FullPath, tuple(layer.Color), layer.Visible) for layer in model.Layers]


@pytest.mark.parametrize("loss", [False, True])
def test_the_spliced_model_is_the_one_rhino3dm_writes_run_by_run(
    two_estimates: EvaluationResult, *, loss: bool
) -> None:
    """Same objects in the same order (runs, pieces, dots), layers and document text."""
    result = with_reference_loss(two_estimates) if loss else two_estimates
    options = ExportOptions(site=parse_site(SITE), evaluation_id="ev-42", title="Lab run")
    placement = place_evaluation(result, options)
    data = rhino.export_3dm(result, options, placement=placement)
    slow = rhino.write_3dm(lambda: rhino._model(placement, bulk=False))
    assert len(data) == len(slow)  # the same records; only the ids differ
    model, expected = rhino3dm.File3dm.FromByteArray(data), rhino3dm.File3dm.FromByteArray(slow)
    runs = sum(len(placement.ate_runs(p)) for p in placement.paths)
    assert len(model.Objects) == len(expected.Objects) > runs > 100
    assert described(model) == described(expected)
    assert layers(model) == layers(expected)
    assert len(model.Strings) == len(expected.Strings) > 0
    keys = [f"loceval.{key}" for key in (*placement.metadata(), "ate_bins", "ate_legend")]
    assert [model.Strings[k] for k in keys] == [expected.Strings[k] for k in keys]
    ids = [obj.Attributes.Id for obj in model.Objects]
    assert len(set(ids)) == len(ids)
    ate = {layer.Index for layer in model.Layers if layer.FullPath.endswith("::ATE")}
    spliced = [o.Attributes.Id for o in model.Objects if o.Attributes.LayerIndex in ate]
    assert len(spliced) == runs
    assert all(i.version == 4 and i.variant == uuid.RFC_4122 for i in spliced)
    assert struct.unpack("<q", data[-8:]) == (len(data),)  # the end-of-file chunk


def test_a_layout_it_does_not_know_is_left_to_rhino3dm(
    two_estimates: EvaluationResult, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A placeholder record unlike the expected layout: rhino3dm writes every run itself."""
    options = ExportOptions(evaluation_id="ev-42")
    placement = place_evaluation(two_estimates, options)
    data = rhino.write_3dm(lambda: rhino._model(placement))
    blocks = [
        rhino_bulk.RunBlock(
            rhino._ate_archives(placement, path),
            placement.ate_run_arrays(path).bin_index,
            rhino._placeholders(placement, path),
        )
        for path in placement.paths[1:]
    ]
    assert rhino_bulk.splice_runs(data, blocks) is not None
    assert rhino_bulk.splice_runs(data[:-1] + b"\1", blocks) is None  # the file's length
    object_id = next(iter(blocks[0].placeholders.values())).bytes_le
    at = data.index(object_id)
    changed = data[: at + 16] + bytes([data[at + 16] ^ 1]) + data[at + 17 :]
    assert rhino_bulk.splice_runs(changed, blocks) is None  # an attribute's CRC
    spliced = rhino3dm.File3dm.FromByteArray(
        rhino.export_3dm(two_estimates, options, placement=placement)
    )
    monkeypatch.setattr(rhino, "splice_runs", lambda _data, _blocks: None)
    fallback = rhino3dm.File3dm.FromByteArray(rhino.export_3dm(two_estimates, options))
    assert len(fallback.Objects) > 100
    assert described(fallback) == described(spliced)


def test_records_are_laid_out_field_after_field() -> None:
    """interleave places each item's fields in order; fill_crc32 checks each item's span."""
    lengths = np.array([2, 0, 3], dtype=np.intp)
    heads = np.array([7, 8, 9], dtype="<u2")
    out, offsets = interleave(
        [rows(heads), (np.frombuffer(b"abcde", dtype=np.uint8), lengths), constant(b"\0" * 4, 3)]
    )
    assert offsets.tolist() == [0, 8, 14, 23]
    assert out[:8].tobytes() == b"\7\0ab\0\0\0\0"
    fill_crc32(out, offsets[:-1], offsets[:-1] + 2 + lengths, offsets[:-1] + 2 + lengths)
    assert out[14:23].tobytes() == b"\t\0cde" + struct.pack("<I", zlib.crc32(b"\t\0cde"))
