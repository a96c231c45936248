"""The toolchain drivers: every subprocess magfab runs for the firmware (avr-gcc, avr-size, avr-objcopy, gcc,
simavr).

* :func:`build_hex` -- the ATmega328P image with avr-gcc (``None`` without avr-gcc), and its flash/RAM size.
* :func:`build_host` -- the core and the simulated MLX90393 compiled for the host with
  ``gcc -std=c99 -Wall -Wextra -Werror -pedantic``, for the tests.
* :func:`build_avr_elf`, :func:`run_simavr` -- an AVR program compiled and run in the simulator.
* :func:`versions`, :func:`build_generic`, :func:`write_generic_image` -- the generic image the wheel ships
  (:func:`magfab.export.firmware.shipped_image`), rebuilt from :func:`~magfab.export.firmware.generic_sources`;
  ``python -m magfab.export.toolchain`` rewrites it and its ``toolchain.json`` in the source tree.

A tool that fails on what we gave it raises :class:`CompileError` (a :class:`~magfab.errors.ToolError`: our
bug, exit 1); a missing tool gives None or FileNotFoundError as each function says.
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import signal
import subprocess
import tempfile
from collections.abc import Mapping
from pathlib import Path, PurePosixPath
from typing import Any

from ..errors import ToolError
from ..formats.uf2 import seal_boot2
from . import rp2040
from .firmware import (
    AVR_CFLAGS,
    AVR_LDFLAGS,
    CORE_DIR,
    CORE_SOURCES,
    F_CPU_HZ,
    FLASH_LIMIT_BYTES,
    GENERIC_DIR,
    GENERIC_TOOLCHAIN,
    HEX_NAME,
    HOST_CFLAGS,
    HOST_PROGRAM,
    MCU,
    RAM_LIMIT_BYTES,
    FirmwareError,
    generic_sources,
)

__all__ = ["CompileError", "build_avr_elf", "build_generic", "build_hex", "build_host", "build_rp2040", "run_simavr",
           "versions", "arm_versions", "build_generic_rp2040", "write_generic_image", "write_tree"]


class CompileError(ToolError):
    """The C compiler (or another tool of the toolchain) failed; the message carries its command and output."""

    def __init__(self, command: list[str], output: str) -> None:
        self.command = command
        self.output = output
        tail = "\n".join(output.strip().splitlines()[-40:])
        super().__init__(f"{Path(command[0]).name} failed ({' '.join(command[1:6])} ...):\n{tail}")


def write_tree(files: Mapping[str, bytes], root: Path) -> None:
    """Write rendered files under root (paths must stay inside it)."""
    for rel, data in files.items():
        parts = PurePosixPath(rel).parts
        if not parts or PurePosixPath(rel).is_absolute() or ".." in parts:
            raise ValueError(f"firmware file path {rel!r} must be relative and stay inside the folder")
        target = root.joinpath(*parts)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)


def _run(command: list[str], cwd: Path, timeout: float = 300.0) -> str:
    try:
        done = subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired as exc:
        raise CompileError(command, f"timed out after {timeout:g} s") from exc
    output = (done.stdout or "") + (done.stderr or "")
    if done.returncode != 0:
        raise CompileError(command, output)
    return output


def build_avr_elf(files: Mapping[str, bytes], workdir: str | Path, program: str = "main") -> tuple[Path, str]:
    """Compile ``avr/<program>.c`` (``main``: the firmware, ``bench``: the cycle benchmark) with the core into
    ``workdir/avr/build/<program>.elf``, with the flags of the bundle's Makefile. Returns the ELF and the
    compiler's warnings (empty when clean). Raises FileNotFoundError without avr-gcc, CompileError on failure."""
    cc = shutil.which("avr-gcc")
    if cc is None:
        raise FileNotFoundError("avr-gcc is not installed (Debian packages gcc-avr and avr-libc)")
    root = Path(workdir)
    write_tree(files, root)
    avr = root / "avr"
    (avr / "build").mkdir(parents=True, exist_ok=True)
    elf = avr / "build" / f"{program}.elf"
    core = [f"../{CORE_DIR}/{s}" for s in CORE_SOURCES]
    warnings = _run([cc, *AVR_CFLAGS, f"-I../{CORE_DIR}", "-o", str(elf), f"{program}.c", *core, *AVR_LDFLAGS], avr)
    return elf, warnings.strip()


def _avr_size(elf: Path) -> dict[str, int]:
    size = shutil.which("avr-size")
    if size is None:
        raise FileNotFoundError("avr-size is not installed (Debian package binutils-avr)")
    text = _run([size, "--format=berkeley", str(elf)], elf.parent)
    row = text.strip().splitlines()[-1].split()
    text_b, data_b, bss_b = (int(v) for v in row[:3])
    return {"flash_bytes": text_b + data_b, "ram_bytes": data_b + bss_b,
            "text_bytes": text_b, "data_bytes": data_b, "bss_bytes": bss_b}


def build_hex(files: Mapping[str, bytes]) -> tuple[bytes, dict[str, Any]] | None:
    """The ATmega328P image (Intel HEX bytes) and its sizes, or None when avr-gcc is not installed.

    The dict holds ``flash_bytes`` (text + data), ``ram_bytes`` (static: data + bss), their limits, and
    ``warnings`` (the compiler's, empty when clean). Raises CompileError if a tool fails, FirmwareError if the
    image does not fit (flash under a 2 KB bootloader, or static RAM leaving less than 512 B of stack)."""
    if shutil.which("avr-gcc") is None or shutil.which("avr-objcopy") is None:
        return None
    with tempfile.TemporaryDirectory(prefix="magfab-avr-") as tmp:
        elf, warnings = build_avr_elf(files, tmp, "main")
        sizes = _avr_size(elf)
        hex_path = elf.with_suffix(".hex")
        _run([shutil.which("avr-objcopy") or "avr-objcopy", "-O", "ihex", "-R", ".eeprom", str(elf), str(hex_path)],
             elf.parent)
        image = hex_path.read_bytes()
    if sizes["flash_bytes"] > FLASH_LIMIT_BYTES:
        raise FirmwareError("valid_region.hull", f"{sizes['flash_bytes']} B of flash",
                            f"the image must fit {FLASH_LIMIT_BYTES} B (use a shorter hull or a lower order)")
    if sizes["ram_bytes"] > RAM_LIMIT_BYTES:
        raise FirmwareError("", f"{sizes['ram_bytes']} B of static RAM", f"must be at most {RAM_LIMIT_BYTES} B")
    info: dict[str, Any] = {**sizes, "flash_limit_bytes": FLASH_LIMIT_BYTES, "ram_limit_bytes": RAM_LIMIT_BYTES,
                            "warnings": warnings}
    return image, info


def build_host(files: Mapping[str, bytes], workdir: str | Path) -> Path:
    """Compile the core, the simulated MLX90393 and the harness for this machine with ``gcc`` and
    :data:`HOST_CFLAGS` (warnings are errors) into ``workdir/host/magfab_host``; returns its path."""
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        raise FileNotFoundError("gcc is not installed (Debian packages gcc and libc6-dev)")
    root = Path(workdir)
    write_tree(files, root)
    host = root / "host"
    exe = root / HOST_PROGRAM
    core = [f"../{CORE_DIR}/{s}" for s in CORE_SOURCES]
    _run([cc, *HOST_CFLAGS, f"-I../{CORE_DIR}", "-I.", "-o", str(exe), "host_main.c", "sim_mlx90393.c", *core, "-lm"],
         host)
    return exe


_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def run_simavr(elf: str | Path, timeout_s: float = 120.0, *, stop_after_s: float | None = None) -> str | None:
    """Run an ATmega328P ELF under simavr at 16 MHz and return what it wrote on USART0 (simavr prints it line
    by line; colour codes are removed here), or None when simavr is not installed.

    Without ``stop_after_s`` the program must end by itself (sleep with interrupts off) within ``timeout_s``.
    With it, simavr is interrupted (SIGINT, which it handles by flushing and exiting) after that many seconds of
    wall time: for firmware that loops forever."""
    simavr = shutil.which("simavr")
    if simavr is None:
        return None
    command = [simavr, "-m", MCU, "-f", str(F_CPU_HZ), str(elf)]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        out, err = proc.communicate(timeout=stop_after_s if stop_after_s is not None else timeout_s)
    except subprocess.TimeoutExpired:
        if stop_after_s is None:
            proc.kill()
            proc.communicate()
            raise CompileError(command, f"simavr did not finish in {timeout_s:g} s") from None
        proc.send_signal(signal.SIGINT)
        try:
            out, err = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
    else:
        if proc.returncode != 0:
            raise CompileError(command, out.decode(errors="replace") + err.decode(errors="replace"))
    return _ANSI.sub("", err.decode("ascii", errors="replace"))  # simavr logs the UART on stderr


# ---- the generic image ---------------------------------------------------------------------------------------


def versions() -> dict[str, str] | None:
    """The AVR toolchain on PATH: the first line of ``avr-gcc --version`` and ``avr-objcopy --version``, and
    avr-libc's ``__AVR_LIBC_VERSION_STRING__``; None without avr-gcc or avr-objcopy. Equal versions (and
    flags, :data:`~magfab.export.firmware.AVR_CFLAGS`) make the same bytes."""
    gcc, objcopy = shutil.which("avr-gcc"), shutil.which("avr-objcopy")
    if gcc is None or objcopy is None:
        return None
    here = Path.cwd()
    macros = subprocess.run([gcc, f"-mmcu={MCU}", "-E", "-dM", "-include", "avr/version.h", "-x", "c", "-"],
                            input="", capture_output=True, text=True, cwd=here, timeout=60)
    libc = re.search(r'__AVR_LIBC_VERSION_STRING__ "([^"]+)"', macros.stdout)
    return {"avr-gcc": _run([gcc, "--version"], here).splitlines()[0].strip(),
            "avr-objcopy": _run([objcopy, "--version"], here).splitlines()[0].strip(),
            "avr-libc": libc.group(1) if libc else "unknown"}


def _sources_sha256(files: Mapping[str, bytes]) -> str:
    digest = hashlib.sha256()
    for rel in sorted(files):
        digest.update(rel.encode() + b"\0" + files[rel] + b"\0")
    return digest.hexdigest()


def build_generic() -> tuple[bytes, dict[str, Any]] | None:
    """The generic image compiled here from :func:`~magfab.export.firmware.generic_sources`, and what
    ``toolchain.json`` records of it (toolchain versions, sizes, the sha256 of the sources and of the image);
    None without the AVR toolchain."""
    files = generic_sources()
    found = versions()
    built = build_hex(files) if found else None
    if built is None:
        return None
    image, sizes = built
    info = {"toolchain": found, "flash_bytes": sizes["flash_bytes"], "ram_bytes": sizes["ram_bytes"],
            "sources_sha256": _sources_sha256(files), "image_sha256": hashlib.sha256(image).hexdigest(),
            "cflags": " ".join((*AVR_CFLAGS, *AVR_LDFLAGS))}
    return image, info


def write_generic_image(folder: Path | None = None) -> Path:
    """Rebuild the generic image and write it with its ``toolchain.json`` into ``folder`` (default: the package's
    ``generic_image``, in the source tree). FileNotFoundError without the AVR toolchain."""
    built = build_generic()
    if built is None:
        raise FileNotFoundError("avr-gcc and avr-objcopy are needed (Debian packages gcc-avr, binutils-avr, avr-libc)")
    image, info = built
    out = Path(folder) if folder is not None else Path(__file__).resolve().parent / GENERIC_DIR
    out.mkdir(parents=True, exist_ok=True)
    (out / HEX_NAME).write_bytes(image)
    (out / GENERIC_TOOLCHAIN).write_text(json.dumps(info, indent=2, sort_keys=True) + "\n")
    return out


# ---- the RP2040 images ---------------------------------------------------------------------------------------


def _arm(tool: str) -> str:
    path = shutil.which(f"arm-none-eabi-{tool}")
    if path is None:
        raise FileNotFoundError(f"arm-none-eabi-{tool} is not installed (Debian packages gcc-arm-none-eabi and "
                                "libnewlib-arm-none-eabi)")
    return path


def build_rp2040(files: Mapping[str, bytes], key: str, workdir: str | Path) -> tuple[bytes, dict[str, Any]]:
    """Board ``key``'s flash contents from the bundle's sources ``files`` (the core and ``rp2040/``), built in
    ``workdir`` with arm-none-eabi-gcc: boot2 (``rp2040/boot2.c`` alone, sealed with its checksum) and the image
    after it (``rp2040/build/<key>.elf``, its symbols for a profile). Returns them and the image's ``flash_bytes``
    (boot2's 256 included), ``ram_bytes`` (static), ``warnings``. FileNotFoundError without the toolchain,
    CompileError on failure."""
    gcc, objcopy, size = _arm("gcc"), _arm("objcopy"), _arm("size")
    root = Path(workdir)
    write_tree(files, root)
    src = root / rp2040.RP2040_DIR
    build = src / "build"
    build.mkdir(parents=True, exist_ok=True)
    _run([gcc, *rp2040.BOOT2_CFLAGS, "-T", "boot2.ld", "-o", "build/boot2.elf", "boot2.c"], src)
    _run([objcopy, "-O", "binary", "build/boot2.elf", "build/boot2.bin"], src)
    elf = build / f"{key}.elf"
    core = [f"../{CORE_DIR}/{s}" for s in CORE_SOURCES]
    warnings = _run([gcc, *rp2040.ARM_CFLAGS, *rp2040.defines(key), f"-I../{CORE_DIR}", "-I.", "-T", "rp2040.ld",
                     "-o", str(elf), *rp2040.RP2040_SOURCES, *core, *rp2040.ARM_LDFLAGS], src)
    _run([objcopy, "-O", "binary", str(elf), str(elf.with_suffix(".bin"))], src)
    row = _run([size, "--format=berkeley", str(elf)], src).strip().splitlines()[-1].split()
    text_b, data_b, bss_b = (int(v) for v in row[:3])
    flash = seal_boot2((build / "boot2.bin").read_bytes()) + elf.with_suffix(".bin").read_bytes()
    return flash, {"flash_bytes": len(flash), "ram_bytes": data_b + bss_b, "text_bytes": text_b, "data_bytes": data_b,
                   "bss_bytes": bss_b, "warnings": warnings.strip()}


def arm_versions() -> dict[str, str] | None:
    """The first lines of ``arm-none-eabi-gcc --version`` and ``arm-none-eabi-objcopy --version``; None without
    them. Equal versions (and :data:`~magfab.export.rp2040.ARM_CFLAGS`) make the same bytes."""
    try:
        gcc, objcopy = _arm("gcc"), _arm("objcopy")
    except FileNotFoundError:
        return None
    here = Path.cwd()
    return {"arm-none-eabi-gcc": _run([gcc, "--version"], here).splitlines()[0].strip(),
            "arm-none-eabi-objcopy": _run([objcopy, "--version"], here).splitlines()[0].strip()}


def build_generic_rp2040() -> tuple[dict[str, bytes], dict[str, Any]] | None:
    """Every RP2040 board's shipped flash contents, compiled here from the generic sources, and what
    ``toolchain-rp2040.json`` records of them; None without the ARM toolchain."""
    found = arm_versions()
    if found is None:
        return None
    files = generic_sources("rp2040")
    images: dict[str, bytes] = {}
    boards: dict[str, Any] = {}
    for key in rp2040.rp2040_boards():
        with tempfile.TemporaryDirectory(prefix="magfab-rp2040-") as tmp:
            flash, sizes = build_rp2040(files, key, tmp)
        images[key] = flash
        boards[key] = {"flash_bytes": sizes["flash_bytes"], "ram_bytes": sizes["ram_bytes"],
                       "image_sha256": hashlib.sha256(flash).hexdigest(), "defines": " ".join(rp2040.defines(key))}
    info = {"toolchain": found, "boards": boards, "sources_sha256": _sources_sha256(files),
            "cflags": " ".join((*rp2040.ARM_CFLAGS, *rp2040.ARM_LDFLAGS))}
    return images, info


def write_generic_rp2040(folder: Path | None = None) -> Path:
    """Rebuild the RP2040 images and write them with ``toolchain-rp2040.json`` into ``folder`` (default: the
    package's ``generic_image``). FileNotFoundError without the ARM toolchain."""
    built = build_generic_rp2040()
    if built is None:
        raise FileNotFoundError("arm-none-eabi-gcc and arm-none-eabi-objcopy are needed (Debian packages "
                                "gcc-arm-none-eabi, libnewlib-arm-none-eabi)")
    images, info = built
    out = Path(folder) if folder is not None else Path(__file__).resolve().parent / GENERIC_DIR
    out.mkdir(parents=True, exist_ok=True)
    for key, flash in images.items():
        (out / rp2040.binary_name(key)).write_bytes(flash)
    (out / rp2040.TOOLCHAIN_JSON).write_text(json.dumps(info, indent=2, sort_keys=True) + "\n")
    return out


if __name__ == "__main__":  # python -m magfab.export.toolchain: regenerate the shipped generic images
    print(f"wrote {write_generic_image()}")
    print(f"wrote {write_generic_rp2040()}")
