"""A corpus of hostile inputs (every format loceval reads), run through the CLI and the API.

:mod:`tests.hostile.bases` writes one small valid input per format with the shared
factories; :mod:`tests.hostile.corpus` corrupts them (and builds hostile zips, bags and
options) into :class:`~tests.hostile.corpus.Case` objects, generated in temporary folders at
test time; nothing large is committed. ``test_cli_corpus`` and ``test_http_corpus`` check
the bad-input contract on every case.
"""
