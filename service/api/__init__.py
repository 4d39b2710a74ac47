"""HTTP routes of the service, one router per resource."""
