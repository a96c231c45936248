"""The generic image: one ATmega328P image for every build, its settings and calibration from the
EEPROM record, shipped ready-built as package data (magfab/export/generic_image) so that a machine without
avr-gcc still gets a ready-to-flash .hex. Here: its sources carry no setting of any spec, the shipped image is
the one its sources make (sha256 recorded beside it), and the wheel's package data takes it. Rebuilding it with
avr-gcc and running it and the shipped one on the simulated bus is in test_simbus.py."""

from __future__ import annotations

import fnmatch
import hashlib
import struct
import tomllib
from pathlib import Path

from test_firmware import make_calibration, spec_variant

from magfab import derive, load_spec
from magfab.export import firmware, rp2040, toolchain
from magfab.formats.uf2 import boot2_sealed
from magfab.spec import Acquisition, Reference, Transport

ROOT = Path(__file__).resolve().parents[2]


def test_every_build_renders_the_generic_sources():
    """Builds that differ in every setting the image uses (name, baud, I2C clock, acquisition, output, OSR,
    DIG_FILT, resolution, gain, temperature) render byte-equal image sources: the settings live in the .eep only."""
    other = spec_variant("zq-other-build", firmware_baud=115200, firmware_i2c_hz=100000,
                         firmware_acquisition=Acquisition.SINGLE, firmware_output=Transport.TEXT,
                         firmware_temperature=False, sensor_osr=1, sensor_dig_filt=1, sensor_resolution=1,
                         sensor_gain_sel=5)
    generic = firmware.generic_sources()
    assert "avr/main.c" in generic and "magfab_readout/src/mf_config.h" in generic
    for spec in (load_spec(None), other):
        files = firmware.render(derive(spec), make_calibration())
        assert {rel: files[rel] for rel in generic} == generic
    own = firmware.render(derive(other), make_calibration(), generic=False)  # negative control: constants compiled in
    assert own["magfab_readout/src/mf_config.h"] != generic["magfab_readout/src/mf_config.h"]
    assert derive(other).spec.name.encode() not in b"".join(generic.values())


def test_the_shipped_image_is_made_from_todays_sources():
    """toolchain.json records the sha256 of the sources the shipped image was built from: a source changed without
    ``python -m magfab.export.toolchain`` fails here, with or without avr-gcc."""
    image, made = firmware.shipped_image()
    assert made["sources_sha256"] == toolchain._sources_sha256(firmware.generic_sources())
    assert made["image_sha256"] == hashlib.sha256(image).hexdigest()
    assert made["cflags"] == " ".join((*firmware.AVR_CFLAGS, *firmware.AVR_LDFLAGS))
    assert set(made["toolchain"]) == {"avr-gcc", "avr-libc", "avr-objcopy"}
    assert made["flash_bytes"] <= firmware.FLASH_LIMIT_BYTES and made["ram_bytes"] <= firmware.RAM_LIMIT_BYTES
    lines = image.decode("ascii").splitlines()
    assert lines[-1] == ":00000001FF" and all(sum(bytes.fromhex(x[1:])) & 0xFF == 0 for x in lines)


def test_the_shipped_rp2040_images_are_made_from_todays_sources():
    """toolchain-rp2040.json records the sha256 of the sources the RP2040 images were built from and of each board's
    image: a source changed without ``python -m magfab.export.toolchain`` fails here. Each image starts with a sealed
    boot2 and the vector table after it (the stack in SRAM, the reset handler in flash, a Thumb address); with
    arm-none-eabi-gcc of the recorded version, today's sources give the same bytes for every board."""
    made = rp2040.shipped_image("pico")[1]
    assert made["sources_sha256"] == toolchain._sources_sha256(firmware.generic_sources("rp2040"))
    assert made["cflags"] == " ".join((*rp2040.ARM_CFLAGS, *rp2040.ARM_LDFLAGS))
    assert sorted(made["boards"]) == sorted(rp2040.rp2040_boards())
    same_compiler = toolchain.arm_versions() == made["toolchain"]
    built = toolchain.build_generic_rp2040() if same_compiler else None
    for key in rp2040.rp2040_boards():
        image, info = rp2040.shipped_image(key)
        assert info["image_sha256"] == hashlib.sha256(image).hexdigest() and info["flash_bytes"] == len(image)
        assert info["defines"] == " ".join(rp2040.defines(key))
        sp, reset = struct.unpack_from("<II", image, 256)
        assert boot2_sealed(image) and 0x20000000 < sp <= 0x20042000 and 0x10000100 < reset < 0x10100000 and reset & 1
        if built is not None:
            assert built[0][key] == image, key


def test_the_wheel_takes_the_shipped_image():
    """pyproject.toml's package data matches every file of magfab/export/generic_image (the wheel test,
    tests/test_packaging.py, checks the built wheel itself)."""
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["magfab.export"]
    folder = ROOT / "magfab" / "export" / firmware.GENERIC_DIR
    shipped = sorted(p.relative_to(folder.parent).as_posix() for p in folder.iterdir() if p.is_file())
    assert shipped == sorted(f"{firmware.GENERIC_DIR}/{name}" for name in (
        firmware.HEX_NAME, firmware.GENERIC_RATE, firmware.GENERIC_TOOLCHAIN, rp2040.TOOLCHAIN_JSON,
        *(rp2040.binary_name(key) for key in rp2040.rp2040_boards())))
    assert all(any(fnmatch.fnmatch(rel, pattern) for pattern in data) for rel in shipped)


#: One setting of MagOne's changed at a time (spec_variant's section_key form) and the setting the build then differs
#: in: another conversion time (OSR, digital filter, no temperature), single measurements, text frames, another baud
#: or I2C clock. Each a build the recorded rate is not of.
OTHER_SETTINGS = {
    "sensor_osr": (1, "tconv_us"), "sensor_dig_filt": (3, "tconv_us"), "firmware_temperature": (False, "tconv_us"),
    "firmware_acquisition": (Acquisition.SINGLE, "acquisition"), "firmware_output": (Transport.TEXT, "output"),
    "firmware_baud": (115200, "baud"), "firmware_i2c_hz": (100000, "i2c_hz"),
}


def test_every_build_quotes_the_measured_rate_and_its_calibration():
    """The shipped image's recorded rate (generic_image/rate.json, held to a new measurement by
    test_simbus_timing.py) is the one firmware.measured_rate gives, with the settings it ran with: a build with those
    settings and a calibration like the measured one quotes it (its firmware README with the calibration it was
    measured with); a build with any one setting otherwise, a calibration of higher order or of another method, or
    an array, quotes no figure and says how it differs (in its firmware README; its build.json, report and
    predictions.json quote none: firmware.measured_rate_for)."""
    measured = firmware.measured_rate()
    assert measured is not None and measured["worst"]["delivered"] >= 0.99
    cal = measured["calibration"]
    magone = derive(load_spec(None))
    assert measured["settings"] == firmware.rate_settings(magone) and cal["spec"] == "magone"
    same = {"method": cal["method"], "order": cal["order"]}
    line = firmware._measured_line(magone, same)
    assert line.startswith("Measured: ") and f"(order {cal['order']}," in line
    assert firmware.measured_rate_for(magone, same) == measured == firmware.measured_rate_for(magone, None)
    lower = {"method": cal["method"], "order": cal["order"] - 1}
    assert firmware.measured_rate_for(magone, lower) == measured  # a lower order costs less a sample
    others = [(magone, {"method": cal["method"], "order": cal["order"] + 2}, "calibration order"),
              (magone, {"method": "mls", "order": cal["order"]}, "a mls calibration"),
              (derive(load_spec(None).model_copy(update={"reference": Reference()})), same, "reference"),
              *((derive(spec_variant(**{key: value})), same, named) for key, (value, named) in OTHER_SETTINGS.items())]
    for design, calibration, named in others:
        assert firmware.measured_rate_for(design, calibration) is None, named
        text = firmware._measured_line(design, calibration)
        assert text.startswith("Not measured for this build") and named in text and "frames/s" not in text, text
