"""The ground floor: vocabulary, units, errors, time and number formatting, geodesy,
distributions, configuration and the process helpers every layer may use.

Nothing here imports from any other dracc package.
"""
