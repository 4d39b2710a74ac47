"""The result document read back: the typed views every reader of a result.json goes through."""
