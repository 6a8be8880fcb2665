"""dracc — voyage log analyser for ships.

Conventions, written once for the whole package
-----------------------------------------------
Units
    A unit suffix on every physical quantity: ``_m``, ``_mps``, ``_rad``, ``_s``,
    ``_ns``, ``_m2``, ``_radps``.  Degrees (``_deg``), knots (``_kn``) and nautical
    miles (``_nmi``) appear only at the edges: ingest of raw sentences and reports.
Angles
    Radians inside.  Every angle difference goes through :func:`dracc.core.geodesy.angdiff`
    into (-pi, pi]; means of angles are taken on the circle
    (:func:`dracc.core.geodesy.circmean`).  Headings and courses are in [0, 2*pi).
Time
    UTC as int64 nanoseconds since the Unix epoch (``time_ns``), as MCAP does.
    Math kernels take float seconds from an explicit epoch.
Frames
    ``N`` north, ``E`` east, ``D`` down; positions are geodetic WGS-84
    (``lat_rad``, ``lon_rad``).  Local offsets are metres north/east.
Roles
    ``compass``, ``log``, ``ins1``, ``ins2``, ``ins3``, ``gnss``.

Equation labels: ``(Bn)`` dead-reckoning paper (seeds/000), ``(Kn)`` INS-deviation
paper (seeds/001), ``(Wn)`` pier-line fusion fragment (seeds/004); see
``METHODS.md`` in the shared folder for the corrected statements.
"""

__version__ = "0.1.0"
