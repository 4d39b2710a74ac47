"""Uploads: receiving files into the blob store, recognising them, the datasets they become."""
