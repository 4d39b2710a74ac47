"""Registration: trajectories associated in time and aligned in space.

Association (:mod:`.association`) and alignment (:mod:`.alignment`) are the steps between
reading a recording and measuring its errors.
"""
