"""Schedules: recurring summary reports, their runs and their webhooks."""
