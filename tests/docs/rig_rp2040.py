"""An RP2040 readout board on the walk's bench: its BOOTSEL drive and the emulated board behind a serial port.

* The drive: ``/media/<user>/RPI-RP2``, the pages' Linux path, ``<user>`` the rig's own name (``$USER`` in
  :attr:`Rp2040Rig.env`), holding the bootrom's ``INFO_UF2.TXT`` as a board in BOOTSEL mode shows it. A .uf2 copied
  onto it, once whole, is what the board runs: the drive goes away (the bootrom reboots into the image) and
  tests/firmware_sim/rp2040/run.mjs starts it (``--interactive``, the checks of every block and of boot2 included),
  with the build's MLX90393 model (its ``sim_mlx90393.c``, behind mlxd.c) on the board's I2C controller at the
  build's address, the bus timed at the image's SCL clock.
* The port: a pseudo-terminal. What the host writes there the emulated USB host sends the board; what the board sends
  over USB comes out there. The emulation runs in 2 ms steps, no faster than the wall clock; what the walk sets (the
  field, a moving stage: rig.Stage, the Uno rig's) is read at each step's middle, on the board's own clock.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import threading
import time
import tty
from pathlib import Path

from conftest import require_node_package, require_tool
from rig import Stage

from magfab.export import rp2040
from magfab.formats.uf2 import write_regions

HARNESS = Path(__file__).resolve().parents[1] / "firmware_sim" / "rp2040"
STEP_US = 2000
INFO_UF2 = "UF2 Bootloader v3.0\nModel: Raspberry Pi RP2\nBoard-ID: RPI-RP2\n"  # the RP2040 bootrom's INFO_UF2.TXT


class Rp2040Rig(Stage):
    """The board and its drive (see the module's docstring)."""

    def __init__(self, build_dir: Path, work: Path) -> None:
        self.build_dir, self.work = Path(build_dir), Path(work)
        self.node = require_node_package(HARNESS, "rp2040js")
        fw = self.build_dir / "firmware"
        self.mlxd = self.work / "mlxd"
        subprocess.run([require_tool("cc"), "-std=gnu99", "-O2", f"-I{fw / 'host'}",
                        f"-I{fw / 'magfab_readout' / 'src'}", "-o", str(self.mlxd), str(HARNESS / "mlxd.c"),
                        str(fw / "host" / "sim_mlx90393.c"), "-lm"], check=True)
        spec = json.loads((self.build_dir / "spec.json").read_text())
        self.key = spec["board"].get("board") or "qtpy-rp2040"  # the spec's board, or the rp2040 default
        settings = json.loads((self.build_dir / "readout" / "src" / "magfab_readout" / "build.json").read_text())
        self.addresses = [settings["image_settings"]["i2c_address"]]
        self.bus = next(d.split("=")[1] for d in rp2040.defines(self.key) if d.startswith("-DMF_RP_I2C="))
        self.user = f"magfab-walk-{os.getpid()}"
        self.drive = Path("/media") / self.user / "RPI-RP2"
        self.env = {"USER": self.user}
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self.master, False)
        self.port = os.ttyname(self._slave)
        self.flashed: Path | None = None
        self.resets = 0
        self._fields = [(0.0, 0.0, 0.0, 25.0)]
        self._track = None  # a stage moving on the board's clock (follow)
        self._sent_field: tuple | None = None
        self._us = 0
        self._proc: subprocess.Popen | None = None
        self._kept: Path | None = None  # the flash as a board left it (bootsel), under the next .uf2 copied
        self._pause = False
        self._running = threading.Event()  # set while the thread is inside a step of the board
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="rp2040-rig", daemon=True)

    def __enter__(self) -> Rp2040Rig:
        self.drive.mkdir(parents=True)
        (self.drive / "INFO_UF2.TXT").write_text(INFO_UF2)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(30)
        if self._proc is not None and self._proc.poll() is None:
            self._proc.kill()
            self._proc.wait(10)
        shutil.rmtree(self.drive.parent, ignore_errors=True)
        os.close(self.master)
        os.close(self._slave)
        if self._error is not None and exc[0] is None:
            raise RuntimeError("the emulated board failed") from self._error

    # ---- what the walk's bench asks of a board ----

    @property
    def error(self) -> BaseException | None:
        return self._error

    @property
    def board_s(self) -> float:
        with self._lock:
            return self._us / 1e6

    def bootsel(self) -> None:
        """The person holds BOOTSEL and plugs the board in again: the running image stops, its flash kept (the image,
        the record's sector and the identity's), and the drive is back; the next .uf2 copied onto it is written over
        that flash as the bootrom writes it (each sector it touches erased first: run.mjs --drop)."""
        with self._lock:
            self._pause = True
        while self._running.is_set():
            time.sleep(0.01)
        if self._proc is not None:
            offset = rp2040.record_offset(rp2040.resolve.board(self.key))
            image = len(rp2040.shipped_image(self.key)[0])
            held = [(at, bytes.fromhex(self._ask(f"peek {at},{n}"))) for at, n in
                    ((0, image), (offset - 4096, 64), (offset, 1024))]
            self._ask_quit()
            self._kept = self.work / "kept.uf2"
            self._kept.write_bytes(write_regions([(0x10000000 + at, data) for at, data in held]))
        self.drive.mkdir(parents=True, exist_ok=True)
        (self.drive / "INFO_UF2.TXT").write_text(INFO_UF2)
        with self._lock:
            self._pause = False

    def _ask_quit(self) -> None:
        assert self._proc is not None and self._proc.stdin is not None
        self._proc.stdin.write("quit\n")
        self._proc.stdin.flush()
        self._proc.wait(30)
        self._proc = None

    # ---- the board ----

    def _copied(self) -> Path | None:
        """A .uf2 on the drive that is whole (whole blocks, its size the same twice 50 ms apart), or None."""
        for path in sorted(self.drive.glob("*.uf2")) if self.drive.is_dir() else ():
            size = path.stat().st_size
            time.sleep(0.05)
            if size and size % 512 == 0 and path.stat().st_size == size:
                return path
        return None

    def _ask(self, line: str) -> str:
        assert self._proc is not None and self._proc.stdin is not None and self._proc.stdout is not None
        self._proc.stdin.write(line + "\n")
        self._proc.stdin.flush()
        answer = self._proc.stdout.readline()
        if not answer:
            raise RuntimeError(f"run.mjs ended: {self._proc.stderr.read() if self._proc.stderr else ''}")
        return answer.strip()

    def _boot(self, uf2: Path) -> None:
        self.flashed = self.work / f"{self.resets}-{uf2.name}"
        shutil.copyfile(uf2, self.flashed)
        shutil.rmtree(self.drive)  # the bootrom reboots into the image: the drive goes away
        with self._lock:
            field = self._fields[0]
        files = [str(self.flashed)] if self._kept is None else [str(self._kept), "--drop", str(self.flashed)]
        self._proc = subprocess.Popen(
            [self.node, str(HARNESS / "run.mjs"), *files, "--interactive", "--mlx", str(self.mlxd),
             "--i2c", self.bus, "--addr", str(self.addresses[0]), "--field", ",".join(map(str, field)), "--bus-timing"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=HARNESS)
        self._sent_field = field
        self.resets += 1

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                with self._lock:  # a step starts only while bootsel has not paused the board
                    paused = self._pause
                    if not paused:
                        self._running.set()
                if paused:
                    time.sleep(0.01)
                    continue
                if self._proc is None:
                    uf2 = self._copied()
                    if uf2 is None:
                        self._running.clear()
                        time.sleep(0.05)
                        continue
                    self._boot(uf2)
                    started, start_us = time.monotonic(), self._us
                try:
                    self._step(started, start_us)
                finally:
                    self._running.clear()
        except BaseException as exc:  # kept for the walk, which reports it
            self._error = exc
            self._running.clear()

    def _step(self, started: float, start_us: int) -> None:
        """Host bytes to the board, one step of the emulation, the board's bytes to the host, paced to the wall."""
        with self._lock:
            if self._track is not None:  # the stage at the step's middle, 25 C (as the Uno rig's)
                self._fields = [(*(float(b) for b in f), 25.0) for f in self._track((self._us + STEP_US / 2) / 1e6)]
            field = self._fields[0]
        if field != self._sent_field:
            self._ask("field " + ",".join(map(str, field)))
            self._sent_field = field
        try:
            data = os.read(self.master, 4096)
        except (BlockingIOError, OSError):
            data = b""
        if data:
            self._proc.stdin.write(f"send {data.hex()}\n")
        out = bytes.fromhex(self._ask(f"run {STEP_US}"))
        if out:
            self._send(out)
        with self._lock:
            self._us += STEP_US
            ahead = (self._us - start_us) / 1e6 - (time.monotonic() - started)
        if ahead > 0:
            time.sleep(ahead)
