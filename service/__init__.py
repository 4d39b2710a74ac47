"""The application layer: the command line and the HTTP service, the two front doors.

``service.cli`` is the command line (a module per command), ``service.main`` builds the HTTP
service; both turn their options into the core's with ``service.options`` and run an
evaluation with ``service.runner``.
"""
