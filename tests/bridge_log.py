"""A research ship's bridge recorder, written line by line for the role tests.

Two gyros each sending ``HEHDT`` (the second also ``TIROT``), a rate-of-turn device
sending only ``TIROT``, an EM log and an ADCP log both sending ``VDVBW`` (each
optionally failed at 0.0 kn), a Seapath under talker ``GP`` (GGA, VTG, HDT, ``PSXN,23``)
and an AIS sending its own ship's ``!AIVDO`` with an integer heading: every line an IEC
61162-450 TAG block with the sender ``s:`` and the logger's millisecond clock ``c:``.

Independent of dracc's writers: checksums by hand (XOR), AIS armour by pyais.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import reduce
from pathlib import Path

import numpy as np

KN = 1852.0 / 3600.0
R_EARTH = 6371000.0


def _cs(body: str) -> str:
    return f"{reduce(lambda a, c: a ^ ord(c), body, 0):02X}"


def tagged(source: str, t_s: float, body: str) -> str:
    """``\\s:src,c:ms*hh\\$BODY*hh``."""
    tag = f"s:{source},c:{int(round(t_s * 1000))}"
    if "*" in body:  # armoured AIS: pyais gave the checksum
        return f"\\{tag}*{_cs(tag)}\\{body}"
    return f"\\{tag}*{_cs(tag)}\\{body[0]}{body[1:]}*{_cs(body[1:])}"


def _latlon(lat_deg: float, lon_deg: float) -> str:
    la, lo = abs(lat_deg), abs(lon_deg)
    return (
        f"{int(la):02d}{(la - int(la)) * 60:08.5f},{'N' if lat_deg >= 0 else 'S'},"
        f"{int(lo):03d}{(lo - int(lo)) * 60:08.5f},{'E' if lon_deg >= 0 else 'W'}"
    )


@dataclass
class Bridge:
    minutes: float = 40.0
    seed: int = 0
    speed_kn: float = 11.0
    gyro2_offset_deg: float = 0.9
    gyro2_outage: bool = True  #: gyro_2 silent for a third of the voyage
    adcp_zero: bool = True  #: the ADCP log reads 0.0 kn throughout
    em_zero: bool = False  #: the EM log reads 0.0 kn throughout
    current_kn: float = 0.4
    start_s: float = 1_780_000_000.0  # 2026-05-28

    def truth(self) -> dict[str, np.ndarray]:
        rng = np.random.default_rng(self.seed)
        n = int(self.minutes * 60)
        t = np.arange(n, dtype=float)
        legs = np.cumsum(rng.uniform(-70, 70, size=n // 600 + 2)) + rng.uniform(0, 360)
        target = legs[(t // 600).astype(int)]
        hdg = np.zeros(n)
        hdg[0] = target[0]
        for i in range(1, n):  # turn at 1 deg/s toward the leg's heading
            hdg[i] = hdg[i - 1] + np.clip(target[i] - hdg[i - 1], -1.0, 1.0)
        stw = self.speed_kn * KN * (1 + 0.05 * np.sin(t / 900.0))
        set_rad = rng.uniform(0, 2 * math.pi)
        vn = stw * np.cos(np.radians(hdg)) + self.current_kn * KN * math.cos(set_rad)
        ve = stw * np.sin(np.radians(hdg)) + self.current_kn * KN * math.sin(set_rad)
        lat = 57.0 + np.cumsum(vn) / R_EARTH * 180 / math.pi
        lon = 11.0 + np.cumsum(ve) / (R_EARTH * math.cos(math.radians(57.0))) * 180 / math.pi
        return {"t": t, "hdg": hdg % 360, "stw": stw, "vn": vn, "ve": ve, "lat": lat, "lon": lon}

    def lines(self) -> list[str]:
        from pyais.encode import encode_dict

        rng = np.random.default_rng(self.seed + 1)
        tr = self.truth()
        out: list[str] = []
        n = tr["t"].size
        outage = (n // 3, 2 * n // 3) if self.gyro2_outage else (n, n)
        for i in range(n):
            t = self.start_s + tr["t"][i]
            h = tr["hdg"][i]
            rot = (tr["hdg"][i] - tr["hdg"][i - 1]) * 60 if i else 0.0
            out.append(
                tagged("gyro_1", t + 0.05, f"$HEHDT,{(h + rng.normal(0, 0.05)) % 360:.1f},T")
            )
            if not outage[0] <= i < outage[1]:
                h2 = (h + self.gyro2_offset_deg + rng.normal(0, 0.05)) % 360
                out.append(tagged("gyro_2", t + 0.10, f"$HEHDT,{h2:.1f},T"))
                out.append(tagged("gyro_2", t + 0.11, f"$TIROT,{rot:.1f},A"))
            out.append(tagged("rot_1", t + 0.12, f"$TIROT,{rot:.1f},A"))
            v = tr["stw"][i] / KN
            em = 0.0 if self.em_zero else v * 1.01 + rng.normal(0, 0.05)
            adcp = 0.0 if self.adcp_zero else v * 0.99 + rng.normal(0, 0.08)
            out.append(tagged("speedlog", t + 0.2, f"$VDVBW,{em:.2f},0.00,A,,,V"))
            out.append(tagged("adcp_speedlog", t + 0.3, f"$VDVBW,{adcp:.2f},0.00,A,,,V"))
            hms = _hms(t)
            la, lo = tr["lat"][i] + rng.normal(0, 2e-6), tr["lon"][i] + rng.normal(0, 3e-6)
            out.append(
                tagged(
                    "seapath", t + 0.4, f"$GPGGA,{hms},{_latlon(la, lo)},2,12,0.8,10.0,M,40.0,M,,"
                )
            )
            cog = math.degrees(math.atan2(tr["ve"][i], tr["vn"][i])) % 360
            sog = math.hypot(tr["vn"][i], tr["ve"][i]) / KN
            out.append(tagged("seapath", t + 0.41, f"$GPVTG,{cog:.1f},T,,M,{sog:.1f},N,,K,D"))
            out.append(
                tagged("seapath", t + 0.42, f"$GPHDT,{(h + rng.normal(0, 0.03)) % 360:.2f},T")
            )
            out.append(tagged("seapath", t + 0.43, f"$PSXN,23,0.5,-0.3,{h % 360:.2f},0.1"))
            if i % 10 == 0:
                msg = {
                    "msg_type": 1,
                    "mmsi": 265123456,
                    "lat": la,
                    "lon": lo,
                    "course": round(cog, 1),
                    "speed": round(sog, 1),
                    "heading": int(round(h)) % 360,
                    "second": int(t % 60),
                }
                for part in encode_dict(
                    msg, talker_id="AI", sentence_type="VDO", radio_channel="A"
                ):
                    out.append(tagged("ais", t + 0.5, part))
        return out

    def write(self, path: Path) -> Path:
        path.write_text("\r\n".join(self.lines()) + "\r\n")
        return path


def _hms(t_s: float) -> str:
    s = t_s % 86400
    return f"{int(s // 3600):02d}{int(s % 3600 // 60):02d}{s % 60:06.3f}"
