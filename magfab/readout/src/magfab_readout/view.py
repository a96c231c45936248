"""``magfab-readout view``: the sensor live in a browser (README.md, "Watch it live").

The readout serves one page (view.html, in this package) and the frames as they arrive, on this computer only
(127.0.0.1): the force on each taxel drawn on the taxel layout, a scrolling time series of Fx, Fy and Fz, the raw
field when asked, the status flags as they happen, and a Zero button (tare). It needs nothing beyond Python's
standard library and a browser, so the base install stays pyserial-only.

Frames reach the page as server-sent events (the browser's EventSource), each a batch of the frames read since the
last, at most :data:`SEND_HZ` a second, so a 543 Hz sensor costs the page 60 small messages a second, not 543. The
page reports back how long a frame took from being read here to being drawn there (its ``/stats``), which the
summary at the end prints: the view's latency measured on the page's own pixels, not estimated."""

from __future__ import annotations

import argparse
import collections
import json
import math
import pkgutil
import sys
import threading
import time
import urllib.parse
from typing import Any, Callable, Deque, Dict, Iterator, List, Optional, Sequence, Tuple

from . import _build
from .cli_shared import Interrupt, Span
from .device import DeviceError
from .usage import UsageError

#: Batches a second the page is sent at most (a display's refresh: more would not be seen).
SEND_HZ = 60.0
#: Frames kept for a page that connects or falls behind (about 4 s of a single taxel at the chip's rate).
KEEP = 2048
#: Samples (an array: cycles) the Zero button averages at rest.
TARE_SAMPLES = 100
#: The largest ``/stats`` body the page sends, bytes.
MAX_STATS_BYTES = 4096
#: What the page's ``/stats`` may hold, and nothing else.
STATS_KEYS = ("drawn", "frames", "latency_median_ms", "latency_p95_ms", "latency_max_ms", "fps")


def add_parser(commands, common) -> None:
    """The ``view`` command and its options, on the command line's subcommands."""
    view = commands.add_parser(
        "view", parents=[common], help="watch the sensor live in a browser (this computer only)",
        description="Serve a live view on this computer (http://127.0.0.1:PORT/) and open it in the browser: the "
        "force on each taxel drawn on its layout, Fx Fy Fz as a scrolling time series, the raw field when asked, "
        "the status flags as they happen (o outside the calibrated region, E chip error, S full scale, R "
        "recovered, M missing) and a Zero button (or the z key) that tares at rest. At the end, on stderr: the "
        "frames read, and the page's own figures (updates drawn, latency from read to drawn).")
    view.add_argument("--http-port", type=int, default=0, metavar="PORT",
                      help="the port to serve on (default: a free one; the address is printed)")
    view.add_argument("--no-browser", action="store_true", help="print the address, do not open a browser")
    view.add_argument("--zero", type=int, default=0, metavar="N",
                      help="average N samples at rest first and subtract that force from the rest (tare)")
    view.add_argument("--count", type=int, metavar="N", help="stop after N samples (an array: N cycles)")
    view.add_argument("--seconds", type=float, metavar="S", help="stop after S seconds of device time")


def _number(x: Optional[float], digits: int) -> Optional[float]:
    """A finite value rounded for the page, or None (JSON has no NaN)."""
    return round(x, digits) if x is not None and math.isfinite(x) else None


def frame_json(time_s: Optional[float], host_s: float, taxels: Sequence[Any]) -> str:
    """One frame as the page reads it: ``{"t", "h", "F", "B", "f", "e"}`` (device and host time, s; per taxel the
    force in N, the field in uT, the five flag letters and the fault's name or null)."""
    return json.dumps({
        "t": _number(time_s, 5), "h": round(host_s, 4),
        "F": [[_number(f, 5) for f in t.force_N] for t in taxels],
        "B": [[_number(b, 2) for b in t.B_uT] for t in taxels],
        "f": [t.flags for t in taxels],
        "e": [t.fault_name for t in taxels],
    }, separators=(",", ":"))


class Hub:
    """What the reading loop and the page's requests share: the latest frames (numbered), the notes to show, a
    pending Zero, and the page's own figures."""

    def __init__(self, meta: dict) -> None:
        self.meta = meta
        self._frames: Deque[Tuple[int, str]] = collections.deque(maxlen=KEEP)
        self._notes: Deque[Tuple[int, str]] = collections.deque(maxlen=64)
        self._count = 0
        self._noted = 0
        self._changed = threading.Condition()
        self.closed = False
        self.tare = threading.Event()
        self.page: Dict[str, float] = {}
        self.pages = 0  # event streams opened
        self.port = 0  # the server's, once it is bound

    def push(self, frame: str) -> None:
        with self._changed:
            self._frames.append((self._count, frame))
            self._count += 1
            self._changed.notify_all()

    def note(self, text: str) -> None:
        with self._changed:
            self._notes.append((self._noted, text))
            self._noted += 1
            self._changed.notify_all()

    def close(self) -> None:
        with self._changed:
            self.closed = True
            self._changed.notify_all()

    def since(self, k: int, j: int, timeout_s: float) -> Tuple[List[str], List[str], int, int]:
        """The frames from number ``k`` on and the notes from number ``j`` on (waiting up to ``timeout_s`` for
        one), and the next ``k`` and ``j``."""
        with self._changed:
            if self._count <= k and self._noted <= j and not self.closed:
                self._changed.wait(timeout_s)
            frames = [f for n, f in self._frames if n >= k]
            notes = [t for n, t in self._notes if n >= j]
            return frames, notes, self._count, self._noted

    def start(self) -> Tuple[int, int]:
        """Where a new page starts: the newest frame, and every note."""
        with self._changed:
            return max(0, self._count - 1), 0

    def take_stats(self, body: bytes) -> None:
        data = json.loads(body.decode("utf-8"))
        if not isinstance(data, dict):
            raise ValueError("not an object")
        self.page = {k: float(data[k]) for k in STATS_KEYS
                     if isinstance(data.get(k), (int, float)) and math.isfinite(data[k])}


def _foreign(headers, port: int) -> bool:
    """A request another site made the browser send (its Origin), or one addressed to another host name that
    resolves here (DNS rebinding): refused, so only the page this server serves talks to it."""
    hosts = {f"127.0.0.1:{port}", f"localhost:{port}"}
    origin = headers.get("Origin")
    return headers.get("Host") not in hosts or (origin is not None and origin not in {f"http://{h}" for h in hosts})


def _handler(hub: Hub, page: bytes) -> type:
    from http.server import BaseHTTPRequestHandler  # lazy: 18 ms that every other readout command would pay

    class Handler(BaseHTTPRequestHandler):
        protocol_version = "HTTP/1.1"

        def log_message(self, format: str, *args: Any) -> None:  # the base class's names
            pass  # the page's requests are not the readout's output

        def _send(self, code: int, kind: str, body: bytes) -> None:
            self.send_response(code)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def do_GET(self) -> None:
            if _foreign(self.headers, hub.port):
                self._send(403, "text/plain; charset=utf-8", b"only the view's own page may ask\n")
                return
            path = urllib.parse.urlsplit(self.path).path
            if path == "/":
                self._send(200, "text/html; charset=utf-8", page)
            elif path == "/meta":
                self._send(200, "application/json", json.dumps(hub.meta).encode("utf-8"))
            elif path == "/events":
                self._events()
            else:
                self._send(404, "text/plain; charset=utf-8", b"not found\n")

        def do_POST(self) -> None:
            if _foreign(self.headers, hub.port):
                self._send(403, "text/plain; charset=utf-8", b"only the view's own page may ask\n")
                return
            length = int(self.headers.get("Content-Length") or 0)
            if not 0 <= length <= MAX_STATS_BYTES:
                self._send(413, "text/plain; charset=utf-8", b"too large\n")
                return
            body = self.rfile.read(length)
            if self.path == "/zero":
                hub.tare.set()
                self._send(202, "text/plain; charset=utf-8", b"zeroing\n")
            elif self.path == "/stats":
                try:
                    hub.take_stats(body)
                except (ValueError, UnicodeDecodeError):
                    self._send(400, "text/plain; charset=utf-8", b"stats must be a JSON object\n")
                    return
                self._send(204, "text/plain; charset=utf-8", b"")
            else:
                self._send(404, "text/plain; charset=utf-8", b"not found\n")

        def _events(self) -> None:
            self.send_response(200)
            self.send_header("Content-Type", "text/event-stream")
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            hub.pages += 1
            k, j = hub.start()
            try:
                while not hub.closed:
                    sent = time.monotonic()
                    frames, notes, k, j = hub.since(k, j, 1.0)
                    body = '{"frames":[' + ",".join(frames) + '],"notes":' + json.dumps(notes) + "}"
                    self.wfile.write(b"data: " + body.encode("utf-8") + b"\n\n")
                    self.wfile.flush()
                    time.sleep(max(0.0, 1.0 / SEND_HZ - (time.monotonic() - sent)))
                self.wfile.write(b"event: end\ndata: {}\n\n")
                self.wfile.flush()
            except (BrokenPipeError, ConnectionResetError):
                return  # the page was closed
            self.close_connection = True

    return Handler


class Server:
    """The page's server on 127.0.0.1, in threads of its own, for the reading loop's lifetime."""

    def __init__(self, hub: Hub, port: int) -> None:
        if not 0 <= port <= 65535:
            raise UsageError(f"--http-port {port}: must be a port number from 0 to 65535 (0: a free one)")
        raw = pkgutil.get_data("magfab_readout", "view.html")
        if raw is None:
            raise DeviceError("this readout package has no view.html: reinstall it from the build's readout folder")
        from http.server import ThreadingHTTPServer  # lazy: as in _handler

        try:
            self.httpd = ThreadingHTTPServer(("127.0.0.1", port), _handler(hub, raw))
        except OSError as exc:
            raise UsageError(f"--http-port {port}: cannot serve on it ({exc.strerror}); give another, or 0 for a "
                             "free one") from None
        self.httpd.daemon_threads = True
        self.hub = hub
        hub.port = self.httpd.server_port
        self.url = f"http://127.0.0.1:{hub.port}/"
        self._thread = threading.Thread(target=self.httpd.serve_forever, name="view", daemon=True)

    def __enter__(self) -> Server:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.hub.close()
        time.sleep(2.0 / SEND_HZ)  # the event streams send their end
        self.httpd.shutdown()
        self.httpd.server_close()


def _summary(span: Span, hub: Hub, cpu_s: float, wall_s: float, what: str, tared: int) -> str:
    text = f"view: {span.n} {what}" + (f" shown ({tared} more went to the zero)" if tared else "") + span.rate(what)
    p = hub.page
    if p:
        text += ("; the page drew {:.0f} updates ({:.0f} frames, {:.0f} a second), from read to drawn median "
                 "{:.1f} ms, p95 {:.1f} ms, most {:.1f} ms").format(
            p.get("drawn", 0), p.get("frames", 0), p.get("fps", 0), p.get("latency_median_ms", math.nan),
            p.get("latency_p95_ms", math.nan), p.get("latency_max_ms", math.nan))
    elif hub.pages == 0:
        text += "; no page was opened"
    if wall_s > 0:
        text += f"; this readout used {cpu_s / wall_s:.0%} of a core"
    return text


def run(args: argparse.Namespace, meta: dict, frames: Callable[[], Iterator[Tuple[Optional[float], Sequence[Any]]]],
        tare: Callable[[int], List[Sequence[float]]], what: str = "samples") -> int:
    """Serve the view while ``frames()`` yields (device time, taxel readings); ``tare(n)`` zeroes over ``n``
    samples and returns each taxel's offset. ``meta`` is what the page shows of the sensor."""
    if args.zero < 0:
        raise UsageError("--zero needs a positive number of samples")
    if args.count is not None and args.count < 1:
        raise UsageError("--count needs a positive number")
    if args.seconds is not None and not args.seconds > 0:
        raise UsageError("--seconds must be positive")
    hub = Hub(meta)
    span = Span()
    stop = Interrupt()  # Ctrl-C ends the view on a whole frame, and the summary follows it
    server = Server(hub, args.http_port)
    wall, cpu = time.monotonic(), time.process_time()
    tared = 0  # samples the Zero button's tares took from the stream
    with server:
        print(f"magfab-readout: view at {server.url} (Ctrl-C to stop)", file=sys.stderr, flush=True)
        if args.zero:
            hub.note(_offsets(tare(args.zero), args.zero))
        if not args.no_browser:
            import webbrowser  # lazy: 6 ms, only when a browser is opened

            webbrowser.open(server.url)
        with stop:
            for time_s, taxels in frames():
                stop.writing = True
                hub.push(frame_json(time_s, time.time(), taxels))
                span.add(time_s)
                stop.writing = False
                if hub.tare.is_set():
                    hub.tare.clear()
                    hub.note(_offsets(tare(TARE_SAMPLES), TARE_SAMPLES))
                    tared += TARE_SAMPLES
                if stop.requested:
                    break
        time.sleep(2.0 / SEND_HZ)  # the last frames reach the page
    print("magfab-readout: " + _summary(span, hub, time.process_time() - cpu, time.monotonic() - wall, what, tared),
          file=sys.stderr)
    return 0


def _offsets(offsets: List[Sequence[float]], n: int) -> str:
    each = "; ".join("{}Fx {:+.4f} N, Fy {:+.4f} N, Fz {:+.4f} N".format(f"taxel {k}: " if len(offsets) > 1 else "",
                                                                         *o) for k, o in enumerate(offsets))
    return f"zero: offset {each} from {n} samples"


def single(args: argparse.Namespace, open_device) -> int:
    """The view of a single taxel's board (``open_device(args, text)`` opens it)."""
    with open_device(args, False) as device:
        meta = {"title": f"{_build.SPEC_NAME}: calibration {device.calibration.short_hash}, {device.port}",
                "taxels": [[0.0, 0.0]], "rate_Hz": _build.SAMPLE_RATE_HZ, "spec": _build.SPEC_NAME}

        def frames() -> Iterator[Tuple[Optional[float], Sequence[Any]]]:
            for sample in device.samples(count=args.count, seconds=args.seconds):
                yield sample.time_s, (sample,)

        return run(args, meta, frames, lambda n: [device.zero(n)])


def array(args: argparse.Namespace, calibration, open_device, reader_of) -> int:
    """The view of an array's board: ``open_device(args, text)`` opens it, ``reader_of(device)`` reads its cycles."""
    with open_device(args, False) as device:
        reader = reader_of(device)
        centres = reader.calibration.compensator.centres
        meta = {"title": f"{_build.SPEC_NAME}: {reader.calibration.taxels} taxels, array.json "
                         f"{reader.calibration.short_hash}, {device.port}",
                "taxels": [[round(c[0], 3), round(c[1], 3)] for c in centres], "rate_Hz": _build.SAMPLE_RATE_HZ,
                "spec": _build.SPEC_NAME}

        def frames() -> Iterator[Tuple[Optional[float], Sequence[Any]]]:
            for cycle in reader.cycles(count=args.count, seconds=args.seconds, keep_up=True):
                yield cycle.time_s, cycle.taxels

        return run(args, meta, frames, lambda n: list(reader.zero(n)), what="cycles")
