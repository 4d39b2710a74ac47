"""LocevalError.reworded: another front door's words, the same error."""

from __future__ import annotations

import pickle

import pytest

from loceval.errors import AlignmentError, LocevalError, ReaderError


@pytest.mark.parametrize("cls", [AlignmentError, ReaderError, LocevalError])
def test_reworded_keeps_the_class_and_code(cls: type[LocevalError]) -> None:
    """The copy has the original's class and code, the new message, and no option to name."""
    original = cls("max_dt_s is too small", option="max_dt_s", suggest="0.1")
    copy = original.reworded("The template 't.json': options.max_dt_s: too small")
    assert type(copy) is cls
    assert copy.code == cls.code
    assert str(copy) == "The template 't.json': options.max_dt_s: too small"
    assert (copy.option, copy.suggest) == (None, None)
    assert (str(original), original.option, original.suggest) == (
        "max_dt_s is too small",
        "max_dt_s",
        "0.1",
    )
    assert str(pickle.loads(pickle.dumps(copy))) == str(copy)  # noqa: S301  (our own bytes)
