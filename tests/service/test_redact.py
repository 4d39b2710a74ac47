"""Server folders out of messages: the private roots are the runtime's, not the process's."""

from __future__ import annotations

from pathlib import Path

from loceval.errors import ReaderError
from service.blobs.local import LocalBlobs
from service.errors import problem_for
from service.redact import scrub

_ID = "0b7c1c7e-8e1f-4c55-9d5e-3c1c9b1a2f00"


def test_a_private_root_outside_the_temp_folder_is_removed_when_given() -> None:
    """A data folder anywhere (here /srv) goes from a message only where it is named."""
    message = f"/srv/site-a/loceval/datasets/{_ID}/run.bag has no topic '/odom'."
    assert scrub(message, private=[Path("/srv/site-a/loceval")]) == (
        "run.bag has no topic '/odom'."
    )
    assert scrub(message, private=[Path("/srv/site-b/loceval")]) == (
        "/srv/site-a/loceval/run.bag has no topic '/odom'."
    )
    assert scrub(message) == "/srv/site-a/loceval/run.bag has no topic '/odom'."


def test_opening_a_store_registers_nothing_for_the_process(tmp_path: Path) -> None:
    """A store names its folder as its own private root; other problems are not affected."""
    store = LocalBlobs(tmp_path / "data")
    try:
        assert store.private_roots == (store.root,)
        err = ReaderError(f"{store.root}/datasets/{_ID}/run.bag is truncated.")
        assert problem_for(err, private=store.private_roots)["detail"] == "run.bag is truncated."
        outside = ReaderError("/srv/other/run.bag is truncated.")
        assert problem_for(outside)["detail"] == "/srv/other/run.bag is truncated."
    finally:
        store.close()
