"""The words every layer shares: sensor roles and the INS accuracy channels.

Defined once here; frames, configuration, methods, audit and reports import them.
"""

from __future__ import annotations

#: the bridge sensors dracc reads, by the part they play
ROLES = ("compass", "log", "ins1", "ins2", "ins3", "gnss")
#: the three INS units compared with the mean of three (METHODS section 4)
INS_ROLES = ("ins1", "ins2", "ins3")

#: the INS accuracy channels: latitude and longitude (as metres) and course
CHANNELS = ("lat", "lon", "course")
#: each channel's key in JSON samples, a priori errors and audit limits (its unit in the name)
CHANNEL_KEYS = {"lat": "lat_m", "lon": "lon_m", "course": "course_deg"}
#: each channel's unit, as reports print it
CHANNEL_UNITS = {"lat": "m", "lon": "m", "course": "deg"}
