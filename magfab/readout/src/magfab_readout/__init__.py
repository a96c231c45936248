"""Host readout for a magfab tactile sensor (the spec it was built for: ``SPEC_NAME``).

Reads the firmware's serial frames, checks them, and gives calibrated force (N), field (uT) and temperature::

    from magfab_readout import Device

    with Device(simulate=True) as device:      # Device("/dev/ttyACM0") for the real board
        device.zero(200)                        # tare: 200 samples at rest
        for sample in device.samples(count=5):
            print(sample.force_N, sample.B_uT, sample.flags)

``Calibration`` evaluates the embedded calibration (``Calibration.embedded()``) from a field, so the host can
recompute and cross-check the firmware's forces; ``decode_frames`` and ``Decoder`` decode raw bytes.

An array build's package reads every taxel (docs/bundle.md section 5): the host computes each taxel's force from
every chip's field::

    from magfab_readout import ArrayReader, Device, SimulatedArray

    with Device(transport=SimulatedArray()) as device:   # Device("/dev/ttyACM0") for the real board
        reader = ArrayReader(device)                      # this package's array.json and taxel calibrations
        reader.zero(200)
        for cycle in reader.cycles(count=5):
            print([taxel.force_N for taxel in cycle])
"""

from typing import Any

try:
    from . import _build
except ImportError as missing:  # the package's source tree without a build's data: only the format validators work
    __version__ = "0+source"  # flit reads it when it installs the bare tree
    _WHY = str(missing)

    def __getattr__(name: str) -> Any:
        raise AttributeError(f"magfab_readout.{name}: {_WHY}")

else:
    from .array_sim import ArrayPressPattern, SimulatedArray
    from .calibration import Calibration, CalibrationError, calibration_sha256
    from .device import (
        CalibrationMismatch,
        CrcErrorRate,
        Device,
        DeviceError,
        NoData,
        PortNotFound,
        cross_check,
        find_port,
    )
    from .frames import (
        Decoder,
        DecoderStats,
        DeviceInfo,
        Sample,
        crc16_ccitt_false,
        decode_frames,
        encode_frame,
        encode_info_line,
        encode_text_line,
    )
    from .simulate import PressPattern, RestTip, SimulatedDevice, TemperatureRamp
    from .taxels import (
        ArrayCalibration,
        ArrayEvaluator,
        ArrayReader,
        Cycle,
        CycleAssembler,
        TaxelReading,
        WrongFirmware,
    )

    __version__ = _build.VERSION
    SPEC_NAME = _build.SPEC_NAME

__all__ = [
    "ArrayCalibration", "ArrayEvaluator", "ArrayPressPattern", "ArrayReader", "Calibration", "CalibrationError",
    "CalibrationMismatch", "CrcErrorRate", "Cycle", "CycleAssembler", "Decoder", "DecoderStats", "Device",
    "DeviceError", "DeviceInfo", "NoData", "PortNotFound", "PressPattern", "RestTip", "SPEC_NAME", "Sample",
    "SimulatedArray", "SimulatedDevice", "TaxelReading", "TemperatureRamp", "WrongFirmware",
    "__version__", "calibration_sha256", "crc16_ccitt_false", "cross_check", "decode_frames", "encode_frame",
    "encode_info_line", "encode_text_line", "find_port",
]
