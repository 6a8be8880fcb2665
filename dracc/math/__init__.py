"""The methods: pure functions over numpy arrays and typed frames, each citing the
equation it implements (METHODS.md).  No I/O, no rendering; imports only
:mod:`dracc.core` and :mod:`dracc.frames`.
"""
