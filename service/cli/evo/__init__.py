"""evo's command lines on loceval's pipeline: ``loceval ape``, ``loceval rpe``, ``loceval res``.

evo (GPL-3.0) is not used: what its flags mean comes from its documentation and from its
observed output (``tests/data/evo_*``). The figures are computed by loceval's core.
"""
