"""What nobody measured, estimated from the motion.

The clock offset (:mod:`.clock`), the device (hand-eye) offset (:mod:`.handeye`), their
shared solvers (:mod:`.common`), and the choice between given and estimated offsets
(:mod:`.offsets`).
"""
