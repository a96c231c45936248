"""Sensor records (format ``magfab-sensors/1``, docs/sensors.md): the one implementation is the readout package's
module (``magfab/readout/src/magfab_readout/records.py``), so ``magfab`` and ``magfab-readout`` read and append the
same records."""

from ..readout.src.magfab_readout.records import (
    EVENT_KINDS,
    FORMAT,
    ID_PATTERN,
    MARKER,
    ROOT_ENV,
    RecordError,
    Sensor,
    check_id,
    create,
    find_root,
    init_root,
    list_sensors,
    now_utc,
    open_sensor,
    owner_of,
    parse_date,
    sha256_hex,
)

__all__ = ["EVENT_KINDS", "FORMAT", "ID_PATTERN", "MARKER", "ROOT_ENV", "RecordError", "Sensor", "check_id", "create",
           "find_root", "init_root", "list_sensors", "now_utc", "open_sensor", "owner_of", "parse_date", "sha256_hex"]
