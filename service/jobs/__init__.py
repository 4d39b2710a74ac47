"""Jobs: the job kinds, the queue, the runner, tracking, the watchdog and the limits."""
