"""NMEA 2000 sources named by the device NAME of their ISO address claim (PGN 60928).

A device's source address (0..253) is negotiated on the bus and may change when a
device joins or restarts; its 64-bit NAME (ISO 11783-5 / J1939-81) does not.  The NAME
bit fields (canboat ``060928-isoAddressClaim.yaml``), from bit 0: unique number (21
bits), manufacturer code (11), device instance lower (3) and upper (5), device function
(8), spare (1), device class (7), system instance (4), industry group (3), arbitrary
address capable (1).

Source keys:

* ``n2k:<manufacturer code>-<unique number>`` (e.g. ``n2k:1851-1240607``, Raymarine
  1851) for a device whose claim the log holds: readable, and the same in every log of
  the vessel.  Where two different NAMEs of one file share manufacturer and unique
  number (one unit presenting several functions), each gets ``-<device function>-<device
  instance>`` appended, and where that still does not tell them apart the NAME itself as
  16 hex digits: ``n2k:<NAME>``.
* ``n2k:addr<source address>`` for messages from an address no claim was seen for (a
  note says so: the key then names the address, which may belong to another device in
  another log).

Address changes: a NAME holds an address from its claim until another NAME claims that
address or the NAME itself claims another one (a device has one address at a time);
after such a move the old address is ``n2k:addr<n>`` until it is claimed again.  The
messages of an address before its first claim in the file are given the NAME of that
first claim (the claim is sent at power-up and on request, so a log usually starts
after it), unless that NAME was seen at another address before.
"""

from __future__ import annotations

import numpy as np

#: NAME bit fields: name -> (first bit, bits)
NAME_FIELDS = {
    "unique_number": (0, 21),
    "manufacturer_code": (21, 11),
    "device_instance_lower": (32, 3),
    "device_instance_upper": (35, 5),
    "device_function": (40, 8),
    "device_class": (49, 7),
    "system_instance": (56, 4),
    "industry_group": (60, 3),
    "arbitrary_address_capable": (63, 1),
}


def name_fields(name: np.ndarray) -> dict[str, np.ndarray]:
    """The NAME bit fields of ``name`` (uint64 array) as int64 arrays."""
    u = np.asarray(name, dtype=np.uint64)
    return {
        k: ((u >> np.uint64(bit)) & np.uint64((1 << n) - 1)).astype(np.int64)
        for k, (bit, n) in NAME_FIELDS.items()
    }


def name_keys(names: list[int]) -> dict[int, str]:
    """Source key of each distinct NAME (see the module docstring)."""
    if not names:
        return {}
    f = name_fields(np.array(names, dtype=np.uint64))
    short = [
        f"n2k:{m}-{u}"
        for m, u in zip(f["manufacturer_code"].tolist(), f["unique_number"].tolist(), strict=True)
    ]
    inst = (f["device_instance_upper"] << 3) | f["device_instance_lower"]
    longer = [
        f"{s}-{fn}-{i}"
        for s, fn, i in zip(short, f["device_function"].tolist(), inst.tolist(), strict=True)
    ]
    out = {}
    for j, nm in enumerate(names):
        if short.count(short[j]) == 1:
            out[nm] = short[j]
        elif longer.count(longer[j]) == 1:
            out[nm] = longer[j]
        else:
            out[nm] = f"n2k:{nm:016X}"
    return out


def source_keys(
    src: np.ndarray,
    claim_row: np.ndarray,
    claim_name: np.ndarray,
    line: np.ndarray | None = None,
) -> tuple[np.ndarray, list[str], list[str]]:
    """The source key of every message: (codes int64 per message, key names, notes).

    ``src``: the source address of each message (file order); ``claim_row`` /
    ``claim_name``: the message indices of the address claims and their NAMEs (uint64);
    ``line``: the messages' line numbers, for the notes.
    """
    n = len(src)
    order = np.argsort(claim_row, kind="stable")
    crow = np.asarray(claim_row, dtype=np.int64)[order]
    cname = [int(x) for x in np.asarray(claim_name, dtype=np.uint64)[order]]
    caddr = [int(a) for a in np.asarray(src)[crow]] if len(crow) else []
    keys_of = name_keys(sorted(set(cname)))
    keys: list[str] = []
    index: dict[str, int] = {}

    def code(key: str) -> int:
        if key not in index:
            index[key] = len(keys)
            keys.append(key)
        return index[key]

    # segments (address, first row, end row, NAME or None) from the claims in file order
    segs: list[tuple[int, int, int, int | None]] = []
    held: dict[int, tuple[int, int]] = {}  # address -> (NAME, since row)
    where: dict[int, int] = {}  # NAME -> address it holds now
    first_at: dict[int, int] = {}  # address -> row of its first claim
    seen_elsewhere: dict[tuple[int, int], bool] = {}  # (address, NAME) claimed elsewhere before
    for r, nm, a in zip(crow.tolist(), cname, caddr, strict=True):
        if a not in first_at:
            first_at[a] = r
            seen_elsewhere[(a, nm)] = nm in where
        old = where.get(nm)
        if old is not None and old != a and held.get(old, (None,))[0] == nm:
            segs.append((old, held[old][1], r, nm))  # the NAME moved: its old address is free
            del held[old]
        if a in held:
            if held[a][0] == nm:
                where[nm] = a
                continue  # a repeated claim
            segs.append((a, held[a][1], r, held[a][0]))
            if where.get(held[a][0]) == a:
                del where[held[a][0]]
        held[a] = (nm, r)
        where[nm] = a
    for a, (nm, r) in held.items():
        segs.append((a, r, n, nm))
    codes = np.full(n, -1, dtype=np.int64)
    notes: list[str] = []
    for a in sorted(first_at):
        rows = np.flatnonzero(src == a)
        mine = sorted((s for s in segs if s[0] == a), key=lambda s: s[1])
        first_nm = next((s[3] for s in mine if s[1] == first_at[a]), None)
        lead = rows[rows < first_at[a]]
        if len(lead) and first_nm is not None and not seen_elsewhere[(a, first_nm)]:
            codes[lead] = code(keys_of[first_nm])
        for _a, r0, r1, owner in mine:
            sel = rows[(rows >= r0) & (rows < r1)]
            if len(sel) and owner is not None:
                codes[sel] = code(keys_of[owner])
    unclaimed = np.unique(np.asarray(src)[codes < 0]).tolist()
    for a in unclaimed:
        codes[(codes < 0) & (src == a)] = code(f"n2k:addr{a}")
    for nm, key in keys_of.items():
        f = {k: int(v[0]) for k, v in name_fields(np.array([nm], dtype=np.uint64)).items()}
        first: dict[int, int] = {}  # address -> row of this NAME's first claim there
        for r, x, a in zip(crow.tolist(), cname, caddr, strict=True):
            if x == nm and a not in first:
                first[a] = r
        addrs = [
            f"{a}" + (f" (line {int(line[r])})" if line is not None else "")
            for a, r in first.items()
        ]
        notes.append(
            f"{key}: NMEA 2000 NAME {nm:016X} (manufacturer {f['manufacturer_code']}, "
            f"device function {f['device_function']}, class {f['device_class']}, instance "
            f"{(f['device_instance_upper'] << 3) | f['device_instance_lower']}) claimed "
            f"address {', '.join(addrs[:5])}"
        )
    if unclaimed:
        notes.append(
            "no address claim (PGN60928) seen for source address "
            f"{', '.join(str(a) for a in unclaimed)}: keyed n2k:addr<address>, which may "
            "name another device in another log"
        )
    return codes, keys, notes
