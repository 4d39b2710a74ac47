"""The application layer: the command line now, the HTTP service later (both front doors)."""
