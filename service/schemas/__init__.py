"""Request and response bodies: shared by the routes, the jobs and the stored requests."""
