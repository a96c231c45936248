// Runs an RP2040 image on rp2040js (tests/firmware_sim/rp2040):
//   node run.mjs IMAGE.uf2 [--drop FILE.uf2] [--boot2] [--until TEXT] [--ms N] [--us N] [--send TEXT] [--hex]
//                [--interactive] [--mlx MLXD --addr A[,A...] [--i2c 0|1] [--addr-b A[,A...] [--i2c-b 0|1]]
//                 --field BX,BY,BZ,T[;...] [--inject FAULT@US]
//                 [--bus-timing] [--reset-phase N [--reset-after US]]]
//
// The image comes as the build's .uf2. Each block is checked as the RP2040 bootrom would take it (UF2's magic numbers,
// the RP2040 family 0xE48BFF56, a 256-byte payload on a page in flash) and written into the emulated flash; boot2's
// checksum (CRC-32/MPEG-2 of its first 252 bytes, little-endian after them) is checked here too, in a second
// implementation beside magfab's, because rp2040js has no bootrom to check it: the emulated core starts at the vector
// table after boot2 (0x10000100) directly, or with --boot2 as the bootrom starts it, boot2 copied to the top of SRAM
// (0x20041f00) and run there (rp2040js's SSI takes boot2's settings without acting on them: this proves boot2 fits,
// runs where the bootrom puts it and starts the image, not that a flash chip answers). rp2040js's USB CDC host is
// attached: it enumerates a device the image brings up and takes what the device sends on its bulk IN endpoint;
// --send's TEXT goes to the device once it is connected. --drop writes a second UF2 file after the first, as the
// bootrom does when a second file is copied onto the drive (each sector the file writes to erased first). The flash
// chip is modelled below the SSI (the NOR model below), so an image can program its own flash. With --mlx, the
// build's MLX90393 model (mlxd, compiled from its sim_mlx90393.c) answers at address A on I2C0 (--i2c 1: I2C1), serving the field BX, BY, BZ (uT) at T (C) (--addr-b: chips on a second
// bus, the other controller or --i2c-b's, timed apart from the first; --field then lists the first bus's chips'
// fields before the second's): each callback of
// rp2040js's I2C asks it synchronously over a FIFO pair (a write is handed over whole at its STOP or repeated START; a
// read's bytes are fixed at its address phase, as the AVR harness does). The bus takes no time, or with --bus-timing
// the time it takes at the SCL clock the image sets (IC_*_SCL_HCNT/LCNT at 125 MHz): each step's completion is held, on
// the emulated clock, for 9 SCL periods for an address or data byte with its ACK bit, one for a START, two for a STOP
// and the bus-free time after it (as the AVR harness times simavr's TWI). --inject FAULT@US injects a fault at US
// microseconds of emulated time: on the bus, nack-addr (the next address phase), nack-data (the next byte written) or
// all-ff (the next read's bytes); inside the chip, chip:NAME (NAME a sim_fault of sim_mlx90393.h: error, short, trunc,
// stuck, reset), as the AVR harness injects them (tests/export/simbus). --reset-phase N restarts the chip (power-on
// registers, RS pending) at the N-th address phase (from the first at or after --reset-after US of emulated time), as
// the AVR harness's bus.reset_in does. UART0's bytes and the CDC's are collected until
// TEXT has been seen in either, N us of emulated time (--us) or N ms of host time (--ms) pass. Prints one JSON line:
// {"boot2_crc_ok", "blocks", "uart", "usb", "usb_hex" (with --hex), "usb_connected", "nanos", "flash" (the NOR
// model's erases, programs, cache flushes and errors), "reset_us" (when --reset-phase struck, or null),
// "bus_busy_us" (how long the bus was busy, every step timed as --bus-timing times it, from --busy-after US of
// emulated time on), "bus_b_busy_us" (the second bus's)}; exit 2 on a refused image. --interactive instead takes commands on stdin, one a line, and runs the emulation only when asked, so that a
// host program can be the board's USB host (tests/export/test_rp2040_harness.py's HarnessTransport):
//   run US      run US microseconds of emulated time; answers with the hex of what the device sent over USB meanwhile
//   send HEX    bytes for the host to send the device (once it is connected)
//   profile     start counting the CPU's cycles by instruction address; the next 'profile' answers with them (JSON)
//   field B,B,B,T  the models' fields (uT) and temperature (C) from now on, as --field gives them; answers ok
//   usb-serial  the device's USB serial number string, asked as a host asks it (JSON)
//   flash       the NOR model's counts and errors (JSON)
//   peek AT,N   N bytes from AT, in hex: a flash offset, or an SRAM address (from 0x20000000)
//   quit
import { ConsoleLogger, LogLevel, Simulator, USBCDC } from 'rp2040js';
import { execFileSync, spawn } from 'child_process';
import { closeSync, mkdtempSync, openSync, readFileSync, readSync, rmSync, writeSync } from 'fs';
import { tmpdir } from 'os';
import { join } from 'path';

const FLASH = 0x10000000, FLASH_END = 0x11000000, FAMILY = 0xe48bff56;

function crc32mpeg2(bytes) {
  let c = 0xffffffff;
  for (const b of bytes) {
    c ^= b << 24;
    for (let k = 0; k < 8; k++) c = (c & 0x80000000) ? ((c << 1) ^ 0x04c11db7) : (c << 1);
    c >>>= 0;
  }
  return c >>> 0;
}

function refuse(why) {
  console.log(JSON.stringify({ refused: why }));
  process.exit(2);
}

const args = process.argv.slice(2);
const option = (name, fallback) => (args.includes(name) ? args[args.indexOf(name) + 1] : fallback);
const until = option('--until', null);
const ms = Number(option('--ms', 2000));
const send = option('--send', '');
const data = readFileSync(args[0]);
const sim = new Simulator();
const mcu = sim.rp2040;
mcu.logger = new ConsoleLogger(LogLevel.Error); // stdout is the report's: the peripherals' debug lines stay out
// A UF2 file as the bootrom takes it: every block checked first, then each page written, its 4 KB sector erased the
// first time the file writes to it (so a file holding only a record leaves the image alone, and vice versa).
const drop = (file, name) => {
  if (file.length === 0 || file.length % 512) refuse(`${name}not whole 512-byte blocks: ${file.length} bytes`);
  const n = file.length / 512, pages = [];
  for (let i = 0; i < n; i++) {
    const at = 512 * i;
    const word = (k) => file.readUInt32LE(at + k);
    if (word(0) !== 0x0a324655 || word(4) !== 0x9e5d5157 || word(508) !== 0x0ab16f30) refuse(`${name}block ${i}: magic`);
    if (!(word(8) & 0x2000) || word(28) !== FAMILY) refuse(`${name}block ${i}: family`);
    const addr = word(12), size = word(16);
    if (size !== 256 || addr % 256 || addr < FLASH || addr + 256 > FLASH_END) refuse(`${name}block ${i}: payload`);
    if (word(20) !== i || word(24) !== n) refuse(`${name}block ${i}: numbering`);
    pages.push([addr - FLASH, file.subarray(at + 32, at + 32 + 256)]);
  }
  const erased = new Set();
  for (const [offset, page] of pages) {
    const sector = offset & ~0xfff;
    if (!erased.has(sector)) mcu.flash.fill(0xff, sector, sector + 0x1000);
    erased.add(sector);
    mcu.flash.set(page, offset);
  }
  return n;
};
const blocks = drop(data, '');
if (args.includes('--drop')) drop(readFileSync(option('--drop')), 'dropped file: ');
const boot2 = mcu.flash.subarray(0, 256);
const stored = (boot2[252] | (boot2[253] << 8) | (boot2[254] << 16) | (boot2[255] << 24)) >>> 0;
const boot2_crc_ok = crc32mpeg2(boot2.subarray(0, 252)) === stored;
if (!boot2_crc_ok) refuse('boot2 checksum');

// The flash chip behind the SSI. rp2040js keeps the SSI's registers and nothing more, and lets a store write its flash
// array. Here a SPI NOR flash answers as the images program it (flash.c), on the bytes the XIP window reads: 06h write
// enable, 20h sector erase (4 KB), 02h page program (within its 256-byte page, bits only cleared), 4Bh unique ID (after
// four dummy bytes, the 8 bytes of --flash-id HEX), 05h status (BUSY
// for the Winbond W25Q16JV datasheet's typical times, 45 ms an erase and 0.4 ms a page) and 03h read. A command is
// the bytes sent while IO_QSPI's SS output override holds the chip select low (GPIO_QSPI_SS_CTRL.OUTOVER 2; 3 ends it).
// What the hardware would not do is an error in the report: a command while busy (but 05h), an erase or program
// without write enable, a read of flash (code or data) while the SSI is out of XIP mode, a store to the XIP window.
const flashId = Buffer.from(option('--flash-id', 'E4630C7D2B4F3F29'), 'hex'); // the chip's unique ID (4Bh)
const nor = { erases: 0, programs: 0, flushes: 0, errors: [], busyUntil: 0, wel: false, low: false, cmd: [], rx: [] };
const ssi = { 0x00: (31 << 16) | (3 << 8), 0x04: 0, 0x08: 1, 0x10: 1, 0x14: 4, 0xf4: (0x03 << 24) | (2 << 8) | (6 << 2) };
const xip = () => ssi[0x08] === 1 && ((ssi[0x00] >> 8) & 3) === 3; // enabled, TMOD EEPROM read: boot2's settings
const norError = (what) => {
  if (nor.errors.length < 20) nor.errors.push(`${what} at ${Math.floor(sim.clock.nanos / 1000)} us, pc 0x${mcu.core.PC.toString(16)}`);
};
const busy = () => sim.clock.nanos < nor.busyUntil;
const norByte = (b) => {
  const c = nor.cmd;
  c.push(b);
  if (c.length === 1) {
    if (busy() && b !== 0x05) norError(`flash command 0x${b.toString(16)} while busy`);
    if (b === 0x06) nor.wel = true;
    return 0xff;
  }
  if (c[0] === 0x05) return (busy() ? 1 : 0) | (nor.wel ? 2 : 0);
  if (c[0] === 0x4b && c.length > 5) return flashId[(c.length - 6) % 8]; // after 4 dummy bytes, the 64-bit ID
  if (c[0] === 0x03 && c.length > 4) return mcu.flash[(((c[1] << 16) | (c[2] << 8) | c[3]) + c.length - 5) & 0xffffff];
  return 0xff;
};
const norEnd = () => {
  const c = nor.cmd;
  nor.cmd = [];
  if ((c[0] !== 0x20 && c[0] !== 0x02) || c.length < 4) return;
  const addr = (c[1] << 16) | (c[2] << 8) | c[3];
  if (!nor.wel) return norError(`flash ${c[0] === 0x20 ? 'erase' : 'program'} without write enable`);
  nor.wel = false;
  if (c[0] === 0x20) {
    mcu.flash.fill(0xff, addr & ~0xfff, (addr & ~0xfff) + 0x1000);
    nor.erases += 1;
    nor.busyUntil = sim.clock.nanos + 45e6;
  } else {
    const page = addr & ~0xff;
    c.slice(4).forEach((v, k) => { mcu.flash[page + ((addr + k) & 0xff)] &= v; });
    nor.programs += 1;
    nor.busyUntil = sim.clock.nanos + 0.4e6;
  }
};
mcu.peripherals[0x18000] = {
  readUint32: (offset) => {
    if (offset === 0x28) return 0x06 | (nor.rx.length ? 0x08 : 0); // SR: TFNF, TFE, RFNE
    if (offset === 0x60) return nor.rx.length ? nor.rx.shift() : 0;
    if (offset === 0x24) return nor.rx.length;
    return ssi[offset] ?? 0;
  },
  writeUint32Atomic: (offset, value) => {
    if (offset !== 0x60) {
      ssi[offset] = value >>> 0;
      return;
    }
    if (ssi[0x08] !== 1 || ((ssi[0x00] >> 8) & 3) !== 0) return norError('SSI data outside transmit-and-receive mode');
    if (!nor.low) norError('SSI data with the chip select not held low');
    nor.rx.push(norByte(value & 0xff));
  },
};
mcu.peripherals[0x40018] = { // IO_QSPI: GPIO_QSPI_SS_CTRL's output override is the chip select
  readUint32: () => 0,
  writeUint32Atomic: (offset, value) => {
    if (offset !== 0x0c) return;
    const over = (value >> 8) & 3;
    if (over === 2 && !nor.low) nor.cmd = [];
    if (over !== 2 && nor.low) norEnd();
    nor.low = over === 2;
  },
};
mcu.peripherals[0x14000] = { // XIP_CTRL: FLUSH
  readUint32: () => 0,
  writeUint32Atomic: (offset) => { if (offset === 0x04) nor.flushes += 1; },
};
const inFlash = (a) => (a >>> 0) >= FLASH && (a >>> 0) < 0x14000000;
for (const name of ['readUint8', 'readUint16', 'readUint32']) {
  const read = mcu[name].bind(mcu);
  mcu[name] = (a) => {
    if (inFlash(a) && !xip()) norError(`read of 0x${(a >>> 0).toString(16)} with the SSI out of XIP mode`);
    return read(a);
  };
}
for (const name of ['writeUint8', 'writeUint16', 'writeUint32']) {
  const write = mcu[name].bind(mcu);
  mcu[name] = (a, v) => (inFlash(a) ? norError(`store to the XIP window at 0x${(a >>> 0).toString(16)}`) : write(a, v));
}
const flashReport = () => ({ erases: nor.erases, programs: nor.programs, flushes: nor.flushes, errors: nor.errors });

let mlx = null, reset_us = null; // reset_us: when --reset-phase restarted the chip
const busNs = [0, 0]; // how long each bus has been busy, at the SCL clock the image sets (--mlx)
if (args.includes('--mlx')) {
  // One model (an mlxd process) per chip: --addr lists the first bus's chips' addresses, --addr-b the second's (on
  // the controller --i2c-b names), --field their fields, in that order (';' between chips, or one for all). A line
  // about a chip goes to the model at its address; a chip's fault (X) to the first.
  const serve = (address) => {
    const dir = mkdtempSync(join(tmpdir(), 'mlxd-'));
    const req = join(dir, 'req'), rep = join(dir, 'rep');
    execFileSync('mkfifo', [req, rep]);
    const child = spawn(option('--mlx'), [req, rep, String(address)], { stdio: 'inherit' });
    const w = openSync(req, 'w'), r = openSync(rep, 'r');
    const one = Buffer.alloc(1);
    const ask = (line) => {
      if (process.env.HARNESS_DEBUG) process.stderr.write(`${Math.floor(sim.clock.nanos / 1000)} ${line}\n`);
      writeSync(w, line + '\n');
      let out = '';
      while (readSync(r, one, 0, 1) === 1 && one[0] !== 10) out += String.fromCharCode(one[0]);
      return out;
    };
    return { address, ask, close: () => { closeSync(w); closeSync(r); child.kill(); rmSync(dir, { recursive: true }); } };
  };
  const list = (name) => (args.includes(name) ? option(name).split(',').map(Number) : []);
  const onA = args.includes('--addr') ? list('--addr') : [12];
  const onB = list('--addr-b');
  const chips = [...onA, ...onB].map(serve);
  const setFields = (text) => {
    const fields = text.split(';');
    chips.forEach((c, k) => c.ask(`F ${(fields[k] ?? fields[0]).split(',').join(' ')}`));
  };
  const ask = (line) => chips[0].ask(line); // the first chip's (a single taxel's: the chip)
  mlx = { ask, setFields, close: () => chips.forEach((c) => c.close()) };
  setFields(option('--field', '0,0,0,25'));
  const now = () => Math.floor(sim.clock.nanos / 1000);
  const pending = { 'nack-addr': 0, 'nack-data': 0, 'all-ff': 0 };
  const CHIP_FAULTS = { error: 1, short: 2, trunc: 3, timeout: 4, stuck: 5, reset: 6 };
  if (args.includes('--inject')) {
    const [fault, at] = option('--inject').split('@');
    sim.clock.createAlarm(() => {
      if (fault.startsWith('chip:')) ask(`X ${CHIP_FAULTS[fault.slice(5)]} 1 ${now()}`);
      else pending[fault] += 1;
    }).schedule(Number(at) * 1000);
  }
  const timed = args.includes('--bus-timing');
  const busyAfter = Number(option('--busy-after', '0')); // the bus's busy time counted from this emulated time, us
  let phases = 0; // address phases from --reset-after on, on either bus (--reset-phase)
  const resetPhase = Number(option('--reset-phase', '0')), resetAfter = Number(option('--reset-after', '0'));
  // A bus: controller i2c with the chips at `addresses` on it (each bus's state and time its own).
  const attach = (i2c, addresses, b) => {
    const at = (address) => (addresses.includes(address) ? chips.find((c) => c.address === address) : undefined);
    let addr = -1, writing = false, wbuf = [], rbuf = [];
    const flush = () => {
      if (addr >= 0 && writing && wbuf.length) at(addr).ask(`W ${addr} ${now()} ${Buffer.from(wbuf).toString('hex')}`);
      wbuf = [];
    };
    const later = (bits, fn) => {
      if (now() >= busyAfter) busNs[b] += bits * (i2c.sclLowPeriod + i2c.sclHighPeriod) * 8;
      if (!timed) return fn();
      sim.clock.createAlarm(fn).schedule(bits * (i2c.sclLowPeriod + i2c.sclHighPeriod) * 8); // 8 ns a cycle
    };
    i2c.onStart = () => { flush(); later(1, () => i2c.completeStart()); };
    i2c.onConnect = (address, mode) => {
      flush();
      if (now() >= resetAfter) phases += 1;
      if (resetPhase && phases === resetPhase && at(address)) {
        at(address).ask(`X ${CHIP_FAULTS.reset} 1 ${now()}`);
        reset_us = now();
      }
      addr = address;
      writing = mode === 0;
      let present = at(address) !== undefined && at(address).ask(`A ${address}`) === '1';
      if (present && pending['nack-addr']) {
        pending['nack-addr'] -= 1;
        present = false;
      }
      if (present && !writing) {
        if (pending['all-ff']) {
          pending['all-ff'] -= 1;
          rbuf = new Array(9).fill(0xff);
        } else {
          const [, hex] = at(address).ask(`R ${address} ${now()} 9`).split(' ');
          rbuf = [...Buffer.from(hex, 'hex')];
        }
      }
      if (!present) addr = -1;
      later(9, () => i2c.completeConnect(present));
    };
    i2c.onWriteByte = (value) => {
      if (pending['nack-data']) {
        pending['nack-data'] -= 1;
        wbuf = [];
        addr = -1;
        later(9, () => i2c.completeWrite(false));
        return;
      }
      wbuf.push(value);
      later(9, () => i2c.completeWrite(true));
    };
    i2c.onReadByte = () => {
      const value = rbuf.length ? rbuf.shift() : 0xff;
      later(9, () => i2c.completeRead(value));
    };
    i2c.onStop = () => { flush(); addr = -1; later(2, () => i2c.completeStop()); };
  };
  attach(mcu.i2c[Number(option('--i2c', '0'))], onA, 0);
  if (onB.length) attach(mcu.i2c[Number(option('--i2c-b', '1'))], onB, 1);
}

let uart = '', usb = '', usb_hex = '', usb_connected = false;
const done = () => {
  sim.stop();
  if (mlx) mlx.close();
  const report = JSON.stringify({ boot2_crc_ok, blocks, uart, usb, usb_hex, usb_connected, nanos: sim.clock.nanos,
    flash: flashReport(), reset_us, bus_busy_us: busNs[0] / 1000, bus_b_busy_us: busNs[1] / 1000 });
  process.stdout.write(report + '\n', () => process.exit(0)); // exit once written: a pipe takes it in pieces
};
const seen = () => {
  if (until !== null && (uart.includes(until) || usb.includes(until))) setImmediate(done);
};
mcu.uart[0].onByte = (b) => {
  uart += String.fromCharCode(b);
  seen();
};
const cdc = new USBCDC(mcu.usbCtrl);
let toSend = [...Buffer.from(send, 'latin1')];
cdc.onDeviceConnected = () => {
  usb_connected = true;
  for (const b of toSend) cdc.sendSerialByte(b);
  toSend = [];
};
cdc.onSerialData = (buffer) => {
  usb += Buffer.from(buffer).toString('latin1');
  if (args.includes('--hex') || args.includes('--interactive')) usb_hex += Buffer.from(buffer).toString('hex');
  seen();
};
if (args.includes('--us')) sim.clock.createAlarm(() => setImmediate(done)).schedule(Number(option('--us')) * 1000);
mcu.core.VTOR = FLASH + 0x100;
mcu.core.reset();
if (args.includes('--boot2')) {
  mcu.core.VTOR = 0;
  mcu.sram.set(mcu.flash.subarray(0, 256), 0x41f00);
  mcu.core.SP = 0x20042000;
  mcu.core.LR = 0;
  mcu.core.PC = 0x20041f00;
}
if (args.includes('--interactive')) {
  const { createInterface } = await import('readline');
  let sent = 0; // usb_hex's characters already answered
  const cycles = new Map(); // with 'profile': cycles by the address of the instruction that took them
  let profiling = false;
  const runFor = (us) => { // Simulator.execute's loop, bounded by emulated time
    const target = sim.clock.nanos + us * 1000;
    while (sim.clock.nanos < target) {
      if (mcu.core.waiting) {
        sim.clock.tick(Math.min(sim.clock.nanosToNextAlarm, target - sim.clock.nanos));
        continue;
      }
      const pc = mcu.core.PC;
      const n = mcu.core.executeInstruction();
      if (profiling) cycles.set(pc, (cycles.get(pc) || 0) + n);
      sim.clock.tick(n * 8); // 125 MHz
    }
  };
  createInterface({ input: process.stdin }).on('line', (line) => {
    const [command, value] = line.trim().split(' ');
    if (command === 'run') {
      runFor(Number(value));
      process.stdout.write(usb_hex.slice(sent) + '\n');
      sent = usb_hex.length;
    } else if (command === 'profile') { // from now on, cycles by instruction address; 'profile' again reports them
      if (profiling) process.stdout.write(JSON.stringify(Object.fromEntries(cycles)) + '\n');
      profiling = !profiling;
      cycles.clear();
    } else if (command === 'field') { // field BX,BY,BZ,T: the chip's field (uT) and temperature (C) from now on
      if (mlx) mlx.setFields(value);
      process.stdout.write('ok\n');
    } else if (command === 'usb-serial') { // the device's serial number string (GET_DESCRIPTOR string 3, US English)
      let got = null;
      const onWrite = mcu.usbCtrl.onEndpointWrite;
      mcu.usbCtrl.onEndpointWrite = (endpoint, buffer) => {
        if (endpoint === 0 && buffer.length > 2 && buffer[1] === 3) got = Buffer.from(buffer.slice(2)).toString('utf16le');
        else onWrite(endpoint, buffer);
      };
      mcu.usbCtrl.sendSetupPacket(new Uint8Array([0x80, 6, 3, 3, 0x09, 0x04, 64, 0]));
      for (let k = 0; k < 50 && got === null; k++) runFor(100);
      mcu.usbCtrl.onEndpointWrite = onWrite;
      process.stdout.write(JSON.stringify(got) + '\n');
    } else if (command === 'flash') { // the flash chip's counts and errors (JSON)
      process.stdout.write(JSON.stringify(flashReport()) + '\n');
    } else if (command === 'peek') { // peek OFFSET N: N bytes of flash from OFFSET, hex
      const [at, n] = value.split(',').map(Number);
      process.stdout.write(Buffer.from(at >= 0x20000000 ? mcu.sram.subarray(at - 0x20000000, at - 0x20000000 + n) : mcu.flash.subarray(at, at + n)).toString('hex') + '\n');
    } else if (command === 'send') {
      const bytes = [...Buffer.from(value || '', 'hex')];
      if (usb_connected) for (const b of bytes) cdc.sendSerialByte(b);
      else toSend.push(...bytes);
    } else {
      if (mlx) mlx.close();
      process.exit(0);
    }
  });
} else {
  sim.execute();
  setTimeout(done, ms);
}
