"""What nobody measured, estimated from the motion.

The clock offset (:mod:`.clock`, from the motion signals of :mod:`.motion`), the clock's drift
and steps along the run (:mod:`.drift`, its model in :mod:`.clockmodel`), the device (hand-eye)
offset (:mod:`.handeye`), their shared solvers (:mod:`.common`), and the choice between given
and estimated offsets (:mod:`.offsets`).
"""
