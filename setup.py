"""Build the optional compiled NMEA scanner; everything else is in pyproject.toml.

``optional=True``: without a C compiler the package still installs and
``dracc.ingest.nmea`` uses its numpy path.
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "dracc.ingest._nmeascan",
            sources=["dracc/ingest/_nmeascan.c"],
            # no fused multiply-add: the same doubles as the numpy path
            extra_compile_args=["-O3", "-ffp-contract=off", "-fno-strict-aliasing"],
            optional=True,
        )
    ]
)
