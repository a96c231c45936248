"""The calibration record the firmware reads from the ATmega328P's EEPROM (docs/bundle.md section 4).

One implementation for both ends: magfab renders the build's .eep with it, and ``magfab-readout upload`` packs a
new calibration.json with it and writes it over serial, so recalibrating needs no compiler and no reflash. It
uses the standard library only, and is loaded by magfab as a file (the package's ``__init__`` needs build.json).

:func:`layout` turns a validated calibration (``calibration_json.validate``) into what the C code evaluates:
Horner rows, the hull without its collinear points as a fan with one edge line per wedge, an inner rectangle;
:func:`pack` lays it out as the record (version, length, CRC-16/CCITT-FALSE) with the image's settings (version 2:
the I2C address and clock, the baud, the chip's register words, the conversion pace and the count scale, all
computed by magfab from the spec, so that one generic image serves every build); :func:`intel_hex` writes bytes as
the Intel HEX an avrdude ``-U eeprom:w:FILE.eep:i`` takes.

A calibration with a ``thermal`` object packs as version 4: version 2's record with a thermal block (the
calibration's temperature T0 and one coefficient a per field axis, float32 each) between the floats and the Horner
rows; the image then corrects the field B / (1 + a (T - T0)) before the calibration. Only when the settings
convert the chip's temperature (``FLAG_TEMPERATURE``, the spec's firmware.temperature): without it the record is
version 2 and nothing is corrected. Images read both versions.

An array (version 3, :func:`pack_array`) carries no force calibration: the settings, every chip's I2C address in
taxel order and the name. The image then reads every chip and sends each one's field; the host computes the
forces (each taxel's calibration and the neighbours' compensation need every taxel's field).
"""

from __future__ import annotations

import binascii
import struct
from typing import Any, Dict, List, Optional, Sequence, Tuple

MAGIC = b"MF"
VERSION = 2
#: Version 2 with the thermal block (T0, a_x, a_y, a_z) at :data:`COEF_OFFSET`, the Horner rows after it.
VERSION_THERMAL = 4
THERMAL = struct.Struct("<4f")
#: Version 4 with a reference block after the thermal block (the reference chip's 7-bit address and its average's
#: shift, two zero bytes), the Horner rows after it.
VERSION_REFERENCE = 5
REFERENCE = struct.Struct("<BBxx")
#: An array's record: the settings and the chips' addresses, no calibration.
VERSION_ARRAY = 3
#: Chips an array's record may list (one I2C bus, the option codes' four addresses times four straps).
MAX_TAXELS = 16
ADDRESSES_OFFSET = 92  # an array record's addresses, after the settings
#: EEPROM of the ATmega328P, bytes; the record starts at address 0.
SIZE = 1024
#: The most a record may take: the EEPROM's last 64 bytes hold the board's sensor identity (identity.py), which
#: ``upload --sensor ID`` writes and no record, .eep or ``upload`` of a record overwrites.
RECORD_MAX = SIZE - 64
HEADER = struct.Struct("<2sBBHH16s4B")  # magic, version, order, length, hull points, sha16, chip settings
#: The image's settings after the header (docs/bundle.md section 4), in this order; the spec name (NAME_LEN bytes
#: of UTF-8) goes at the record's end, before the CRC.
SETTINGS = struct.Struct("<6BH2IH6H4I3H3f")
SETTING_KEYS = ("i2c_address", "twbr", "twps_bits", "flags", "zyxt", "name_len", "ubrr", "baud", "i2c_hz",
                "i2c_timeout_us", "reg0_mask", "reg0_value", "reg1_mask", "reg1_value", "reg2_mask", "reg2_value",
                "tconv_us", "read_margin_us", "retry_us", "exit_wait_us", "raw_zero", "raw_limit", "t_raw_25c",
                "lsb_xy_uT", "lsb_z_uT", "t_c_per_lsb")
#: Bits of the settings' ``flags``.
FLAG_BURST, FLAG_TEMPERATURE, FLAG_TEXT, FLAG_RAW_SIGNED = 1, 2, 4, 8
NAME_MAX = 64
#: The baud of an image without a valid record (it has nothing else to go by): the spec's default. ``upload``
#: falls back to it when the board does not answer at the build's baud.
FALLBACK_BAUD = 250000
SETTINGS_OFFSET = HEADER.size  # 28
FLOATS = ("bz_center", "bz_inv_scale", "br_center", "br_inv_scale", "shear_sign", "direction_min_uT", "tare_fz",
          "tare_fr", "bz_lo", "bz_hi", "br_lo", "br_hi", "in_bz_lo", "in_bz_hi", "in_br_lo", "in_br_hi",
          "p0_bz", "p0_br")
FLOATS_OFFSET = SETTINGS_OFFSET + SETTINGS.size  # 92
COEF_OFFSET = FLOATS_OFFSET + 4 * len(FLOATS)  # 164
FLOAT32_MAX = 3.4028234663852886e38
MAX_ORDER = 8
INPUTS = ("Bz_uT", "Br_uT")


class EepromError(ValueError):
    """A calibration the record cannot hold: ``key`` (path in calibration.json), ``value`` and what is allowed."""

    def __init__(self, key: str, value: object, allowed: str) -> None:
        self.key, self.value, self.allowed = key, value, allowed
        shown = repr(value)
        super().__init__("calibration.{} = {}: {}".format(key, shown if len(shown) <= 80 else shown[:77] + "...",
                                                          allowed))


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF), the frames' checksum."""
    return binascii.crc_hqx(bytes(data), 0xFFFF)


def _f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def _float32(key: str, value: float) -> float:
    if not abs(value) <= FLOAT32_MAX:
        raise EepromError(key, value, "must be finite and within float32 range")
    return value


def _cross(o: Sequence[float], a: Sequence[float], b: Sequence[float]) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def clean_hull(checked: Any) -> List[Tuple[float, float]]:
    """The validated hull (convex, counter-clockwise) without its collinear or numerically flat vertices: each
    costs the firmware an edge test on every reading."""
    key = "valid_region.hull"
    pts = [(_float32(f"{key}[{n}][0]", x), _float32(f"{key}[{n}][1]", y))
           for n, (x, y) in enumerate(checked.hull)]
    tol = 1e-9 * checked.span * checked.span
    changed = True
    while changed and len(pts) > 3:
        changed = False
        for k in range(len(pts)):
            if _cross(pts[k - 1], pts[k], pts[(k + 1) % len(pts)]) <= tol or pts[k] == pts[k - 1]:
                del pts[k]
                changed = True
                break
    return pts


def _inside(hull: List[Tuple[float, float]], q: Tuple[float, float]) -> bool:
    return all(_cross(hull[k - 1], hull[k], q) >= 0.0 for k in range(len(hull)))


def _f32_step(f: float, towards: float) -> float:
    """The next float32 after f in the direction of ``towards``."""
    bits = struct.unpack("<I", struct.pack("<f", f))[0]
    up = towards > f
    if f == 0.0:
        return struct.unpack("<f", struct.pack("<I", 1 if up else 0x80000001))[0]
    bits += 1 if (f > 0) == up else -1
    return struct.unpack("<f", struct.pack("<I", bits))[0]


def inner_box(hull: List[Tuple[float, float]]) -> Tuple[float, float, float, float]:
    """(Bz lo, Bz hi, Br lo, Br hi) of a rectangle inside the convex hull: centred on the vertices' mean, with the
    hull's aspect, as large as keeps its corners inside, rounded inwards to float32. Readings in it skip the
    hull test; an empty box (lo > hi) when none fits."""
    cz = sum(p[0] for p in hull) / len(hull)
    cr = sum(p[1] for p in hull) / len(hull)
    hz = (max(p[0] for p in hull) - min(p[0] for p in hull)) / 2.0
    hr = (max(p[1] for p in hull) - min(p[1] for p in hull)) / 2.0

    def fits(t: float) -> bool:
        return all(_inside(hull, (cz + a * t * hz, cr + b * t * hr)) for a in (-1, 1) for b in (-1, 1))

    if not fits(0.0):
        return (1.0, -1.0, 1.0, -1.0)
    lo, hi = 0.0, 1.0
    for _ in range(60):
        mid = (lo + hi) / 2.0
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    t = lo * (1.0 - 1e-6)
    out = []
    for k, x in enumerate((cz - t * hz, cz + t * hz, cr - t * hr, cr + t * hr)):
        f = _f32(x)
        if (k % 2 == 0 and f < x) or (k % 2 == 1 and f > x):
            f = _f32_step(f, towards=x)
        out.append(f)
    return (out[0], out[1], out[2], out[3])


def layout(checked: Any) -> Dict[str, Any]:
    """What the firmware evaluates, from a validated calibration (``calibration_json.validate``'s result)."""
    order = checked.order
    if order > MAX_ORDER:
        raise EepromError("order", order, f"must be an integer from 0 to {MAX_ORDER}")
    index = {m: n for n, m in enumerate(checked.monomials)}
    # Horner rows: for i = n down to 0, the coefficients of u^i v^j for j = n - i down to 0.
    rows: List[Dict[str, Any]] = [{"i": i, "fz": [], "fr": []} for i in range(order, -1, -1)]
    for force, name in (("Fz_N", "fz"), ("Fr_N", "fr")):
        values = [_float32(f"coefficients.{force}[{m}]", x)
                  for m, x in enumerate(checked.coefficients[force])]
        for row in rows:
            row[name] = [values[index[(row["i"], j)]] for j in range(order - row["i"], -1, -1)]
    scale = {}
    for k, name in enumerate(INPUTS):
        s = checked.scale[k]
        if not 1e-30 < s < 1e30:
            raise EepromError(f"scaling.{name}.scale", s, "must be between 1e-30 and 1e30 (float32 reciprocal)")
        scale[name] = (_float32(f"scaling.{name}.center", checked.center[k]), s)
    box = {name: tuple(_float32(f"valid_region.{name}[{k}]", x) for k, x in enumerate(pair))
           for name, pair in zip(INPUTS, checked.box)}
    hull = clean_hull(checked)
    edges = []
    for k in range(len(hull)):
        (x0, y0), (x1, y1) = hull[k], hull[(k + 1) % len(hull)]
        ex, ey = -(y1 - y0), x1 - x0
        edges.append((ex, ey, ex * x0 + ey * y0))
    inner = inner_box(hull)
    return {
        "order": order, "n_coef": (order + 1) * (order + 2) // 2, "rows": rows,
        "bz_center": scale["Bz_uT"][0], "bz_scale": scale["Bz_uT"][1], "bz_inv_scale": 1.0 / scale["Bz_uT"][1],
        "br_center": scale["Br_uT"][0], "br_scale": scale["Br_uT"][1], "br_inv_scale": 1.0 / scale["Br_uT"][1],
        "shear_sign": float(checked.shear_sign),
        "direction_min_uT": _float32("direction_min_uT", checked.direction_min_uT),
        "tare_fz": _float32("tare_N.Fz_N", checked.tare_N[0]), "tare_fr": _float32("tare_N.Fr_N", checked.tare_N[1]),
        "bz_lo": box["Bz_uT"][0], "bz_hi": box["Bz_uT"][1], "br_lo": box["Br_uT"][0], "br_hi": box["Br_uT"][1],
        "in_bz_lo": inner[0], "in_bz_hi": inner[1], "in_br_lo": inner[2], "in_br_hi": inner[3],
        "p0_bz": hull[0][0], "p0_br": hull[0][1],
        "hull": hull, "fan": [(x - hull[0][0], y - hull[0][1]) for x, y in hull], "edges": edges, "inner": inner,
        "thermal": _thermal(checked),
    }


def _thermal(checked: Any) -> Any:
    """(T0 degC, a_x, a_y, a_z per degC) of the calibration's ``thermal`` object, None without one."""
    t = getattr(checked, "thermal", None)
    if t is None:
        return None
    return (_float32("thermal.reference_C", t.reference_C),
            *(_float32("thermal.coefficient_per_C", a) for a in t.coefficient_per_C))


def pack(lay: Dict[str, Any], sha16: str, settings: Dict[str, Any]) -> bytes:
    """The EEPROM record: header (magic, version, order, length, hull points, the calibration hash's first 16 hex
    digits for the info line, the chip settings gain_sel / resolution / osr / dig_filt it was made for), the
    image's settings (``settings``: those four, :data:`SETTING_KEYS` but ``name_len``, and ``name``, the spec
    name), the floats, the thermal block (version 4: a calibration with ``thermal`` and settings that convert the
    temperature), the Horner rows (per row its Fz then its Fr coefficients), the hull fan and edge lines, the
    name, the CRC. :class:`EepromError` when it does not fit before the sensor identity (:data:`RECORD_MAX`)."""
    n = len(lay["hull"])
    spec_name = settings["name"].encode("utf-8")
    if len(spec_name) > NAME_MAX:
        raise EepromError("name", settings["name"], f"must be at most {NAME_MAX} bytes of UTF-8 in the record")
    block = SETTINGS.pack(*(len(spec_name) if key == "name_len" else settings[key] for key in SETTING_KEYS))
    body = block + b"".join(struct.pack("<f", lay[name]) for name in FLOATS)
    thermal = lay.get("thermal") if settings["flags"] & FLAG_TEMPERATURE else None
    reference = settings.get("reference")
    if reference is not None:  # version 5: the thermal block (none: T0 25 C and no correction), then the reference's
        shift = int(settings["reference_shift"])
        if not 0x08 <= reference <= 0x77 or reference == settings["i2c_address"] or not 1 <= shift <= 8:
            raise EepromError("reference", reference, "must be a 7-bit address from 0x08 to 0x77 other than the "
                              "sensing chip's, with an average's shift from 1 to 8")
        body += THERMAL.pack(*(thermal or (25.0, 0.0, 0.0, 0.0))) + REFERENCE.pack(reference, shift)
    elif thermal is not None:
        body += THERMAL.pack(*thermal)
    for row in lay["rows"]:
        body += struct.pack("<{}f".format(2 * len(row["fz"])), *row["fz"], *row["fr"])
    body += (b"".join(struct.pack("<2f", *p) for p in lay["fan"])
             + b"".join(struct.pack("<3f", *e) for e in lay["edges"]))
    body += spec_name
    length = HEADER.size + len(body) + 2
    if length > RECORD_MAX:
        raise EepromError("valid_region.hull", "{} points at order {}".format(n, lay["order"]),
                          f"the record takes {length} B, the EEPROM holds {RECORD_MAX} B before the sensor identity: "
                          "use a shorter hull or a lower order")
    chip = (settings["gain_sel"], settings["resolution"], settings["osr"], settings["dig_filt"])
    version = VERSION_REFERENCE if reference is not None else VERSION if thermal is None else VERSION_THERMAL
    head = HEADER.pack(MAGIC, version, lay["order"], length, n, sha16.encode("ascii"), *chip)
    record = head + body
    return record + struct.pack("<H", crc16(record))


def pack_array(addresses: Sequence[int], sha16: str, settings: Dict[str, Any], buses: Optional[int] = None) -> bytes:
    """An array's record (version 3): the header (byte 3 the number of taxels N, bytes 6..7 ``buses``: bit k set
    for taxel k on the board's second I2C bus, 0 for every taxel on the first; None: the settings' ``taxel_buses``,
    0 without), the image's settings as in :func:`pack` (their ``i2c_address`` taxel 0's), the N chip addresses in
    taxel order (uint8 each), the name, the CRC. ``sha16`` is the info line's hash (of the build's calibration). An
    image of one bus (the ATmega328P's) refuses a record with a second."""
    if buses is None:
        buses = int(settings.get("taxel_buses", 0))
    n = len(addresses)
    if not 1 <= n <= MAX_TAXELS or len(set(addresses)) != n or not all(0x08 <= a <= 0x77 for a in addresses):
        raise EepromError("taxels", list(addresses),
                          f"must be 1 to {MAX_TAXELS} distinct 7-bit addresses from 0x08 to 0x77")
    if not 0 <= buses < 1 << n:
        raise EepromError("buses", buses, f"must be a mask of the {n} taxels' bits (0 to {(1 << n) - 1})")
    spec_name = settings["name"].encode("utf-8")
    if len(spec_name) > NAME_MAX:
        raise EepromError("name", settings["name"], f"must be at most {NAME_MAX} bytes of UTF-8 in the record")
    block = SETTINGS.pack(*(len(spec_name) if key == "name_len" else settings[key] for key in SETTING_KEYS))
    body = block + bytes(addresses) + spec_name
    length = HEADER.size + len(body) + 2
    chip = (settings["gain_sel"], settings["resolution"], settings["osr"], settings["dig_filt"])
    record = HEADER.pack(MAGIC, VERSION_ARRAY, n, length, buses, sha16.encode("ascii"), *chip) + body
    return record + struct.pack("<H", crc16(record))


def buses(data: bytes) -> int:
    """An array record's buses mask (bit k: taxel k on the second I2C bus); 0 for a single taxel's."""
    head = unpack_header(data)
    return head["hull_points"] if head["version"] == VERSION_ARRAY else 0


def addresses(data: bytes) -> List[int]:
    """The chip addresses of an array record (version 3), in taxel order; [] for a single taxel's."""
    head = unpack_header(data)
    return list(data[ADDRESSES_OFFSET:ADDRESSES_OFFSET + head["order"]]) if head["version"] == VERSION_ARRAY else []


def thermal(data: bytes) -> Any:
    """(T0 degC, a_x, a_y, a_z per degC) of a version-4 or -5 record, None for any other."""
    if len(data) < COEF_OFFSET + THERMAL.size or unpack_header(data)["version"] not in (VERSION_THERMAL,
                                                                                          VERSION_REFERENCE):
        return None
    return THERMAL.unpack_from(data, COEF_OFFSET)


def reference(data: bytes) -> Any:
    """(address, shift) of a version-5 record's reference chip, None for any other."""
    at = COEF_OFFSET + THERMAL.size
    if len(data) < at + REFERENCE.size or unpack_header(data)["version"] != VERSION_REFERENCE:
        return None
    return REFERENCE.unpack_from(data, at)


def unpack_header(data: bytes) -> Dict[str, Any]:
    """The header fields of a record read back (no CRC check: see :func:`check`); ``image`` holds the image's
    settings (:data:`SETTING_KEYS`) when ``data`` reaches past them. An array's record (version 3) has its number
    of taxels where a single taxel's has its order."""
    magic, version, order, length, n, sha16, *settings = HEADER.unpack_from(data, 0)
    out = {"magic": magic, "version": version, "order": order, "length": length, "hull_points": n,
           "sha16": sha16.decode("ascii", "replace"), "settings": tuple(settings)}
    if len(data) >= FLOATS_OFFSET:
        out["image"] = dict(zip(SETTING_KEYS, SETTINGS.unpack_from(data, SETTINGS_OFFSET)))
    return out


def check(data: bytes) -> bool:
    """Whether ``data`` starts with a whole record whose magic, version and CRC are right."""
    if len(data) < HEADER.size + 2:
        return False
    head = unpack_header(data)
    length = head["length"]
    return (head["magic"] == MAGIC and head["version"] in (VERSION, VERSION_THERMAL, VERSION_REFERENCE, VERSION_ARRAY)
            and HEADER.size + 2 <= length <= min(SIZE, len(data))
            and struct.unpack_from("<H", data, length - 2)[0] == crc16(data[:length - 2]))


def intel_hex(data: bytes, start: int = 0) -> bytes:
    """``data`` as Intel HEX records of 16 bytes from address ``start``, with the end-of-file record."""
    lines = []
    for k in range(0, len(data), 16):
        chunk = data[k:k + 16]
        rec = struct.pack(">BHB", len(chunk), start + k, 0) + chunk
        lines.append(f":{rec.hex().upper()}{(-sum(rec)) & 0xFF:02X}")
    lines.append(":00000001FF")
    return ("\n".join(lines) + "\n").encode("ascii")
