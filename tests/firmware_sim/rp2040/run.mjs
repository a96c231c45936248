// Runs an RP2040 image on rp2040js (tests/firmware_sim/rp2040):
//   node run.mjs IMAGE.uf2 [--boot2] [--until TEXT] [--ms N] [--us N] [--send TEXT] [--hex] [--interactive]
//                [--mlx MLXD --addr A --field BX,BY,BZ,T [--inject FAULT@US] [--bus-timing]]
//
// The image comes as the build's .uf2. Each block is checked as the RP2040 bootrom would take it (UF2's magic numbers,
// the RP2040 family 0xE48BFF56, a 256-byte payload on a page in flash) and written into the emulated flash; boot2's
// checksum (CRC-32/MPEG-2 of its first 252 bytes, little-endian after them) is checked here too, in a second
// implementation beside magfab's, because rp2040js has no bootrom to check it: the emulated core starts at the vector
// table after boot2 (0x10000100) directly, or with --boot2 as the bootrom starts it, boot2 copied to the top of SRAM
// (0x20041f00) and run there (rp2040js's SSI takes boot2's settings without acting on them: this proves boot2 fits,
// runs where the bootrom puts it and starts the image, not that a flash chip answers). rp2040js's USB CDC host is
// attached: it enumerates a device the image brings up and takes what the device sends on its bulk IN endpoint;
// --send's TEXT goes to the device once it is connected. With --mlx, the build's MLX90393 model (mlxd, compiled from
// its sim_mlx90393.c) answers at address A on I2C0, serving the field BX, BY, BZ (uT) at T (C): each callback of
// rp2040js's I2C asks it synchronously over a FIFO pair (a write is handed over whole at its STOP or repeated START; a
// read's bytes are fixed at its address phase, as the AVR harness does). The bus takes no time, or with --bus-timing
// the time it takes at the SCL clock the image sets (IC_*_SCL_HCNT/LCNT at 125 MHz): each step's completion is held, on
// the emulated clock, for 9 SCL periods for an address or data byte with its ACK bit, one for a START, two for a STOP
// and the bus-free time after it (as the AVR harness times simavr's TWI). --inject FAULT@US injects a fault at US
// microseconds of emulated time: on the bus, nack-addr (the next address phase), nack-data (the next byte written) or
// all-ff (the next read's bytes); inside the chip, chip:NAME (NAME a sim_fault of sim_mlx90393.h: error, short, trunc,
// stuck, reset), as the AVR harness injects them (tests/export/simbus). UART0's bytes and the CDC's are collected until
// TEXT has been seen in either, N us of emulated time (--us) or N ms of host time (--ms) pass. Prints one JSON line:
// {"boot2_crc_ok", "blocks", "uart", "usb", "usb_hex" (with --hex), "usb_connected", "nanos"}; exit 2 on a refused
// image. --interactive instead takes commands on stdin, one a line, and runs the emulation only when asked, so that a
// host program can be the board's USB host (tests/export/test_rp2040_harness.py's HarnessTransport):
//   run US      run US microseconds of emulated time; answers with the hex of what the device sent over USB meanwhile
//   send HEX    bytes for the host to send the device (once it is connected)
//   profile     start counting the CPU's cycles by instruction address; the next 'profile' answers with them (JSON)
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
if (data.length === 0 || data.length % 512) refuse(`not whole 512-byte blocks: ${data.length} bytes`);

const sim = new Simulator();
const mcu = sim.rp2040;
mcu.logger = new ConsoleLogger(LogLevel.Error); // stdout is the report's: the peripherals' debug lines stay out
const blocks = data.length / 512;
for (let i = 0; i < blocks; i++) {
  const at = 512 * i;
  const word = (k) => data.readUInt32LE(at + k);
  if (word(0) !== 0x0a324655 || word(4) !== 0x9e5d5157 || word(508) !== 0x0ab16f30) refuse(`block ${i}: magic`);
  if (!(word(8) & 0x2000) || word(28) !== FAMILY) refuse(`block ${i}: family`);
  const addr = word(12), size = word(16);
  if (size !== 256 || addr % 256 || addr < FLASH || addr + 256 > FLASH_END) refuse(`block ${i}: payload`);
  if (word(20) !== i || word(24) !== blocks) refuse(`block ${i}: numbering`);
  mcu.flash.set(data.subarray(at + 32, at + 32 + 256), addr - FLASH);
}
const boot2 = mcu.flash.subarray(0, 256);
const stored = (boot2[252] | (boot2[253] << 8) | (boot2[254] << 16) | (boot2[255] << 24)) >>> 0;
const boot2_crc_ok = crc32mpeg2(boot2.subarray(0, 252)) === stored;
if (!boot2_crc_ok) refuse('boot2 checksum');

let mlx = null;
if (args.includes('--mlx')) {
  const dir = mkdtempSync(join(tmpdir(), 'mlxd-'));
  const req = join(dir, 'req'), rep = join(dir, 'rep');
  execFileSync('mkfifo', [req, rep]);
  const child = spawn(option('--mlx'), [req, rep, option('--addr', '12')], { stdio: 'inherit' });
  const w = openSync(req, 'w'), r = openSync(rep, 'r');
  const one = Buffer.alloc(1);
  const ask = (line) => {
    if (process.env.HARNESS_DEBUG) process.stderr.write(`${Math.floor(sim.clock.nanos / 1000)} ${line}\n`);
    writeSync(w, line + '\n');
    let out = '';
    while (readSync(r, one, 0, 1) === 1 && one[0] !== 10) out += String.fromCharCode(one[0]);
    return out;
  };
  mlx = { ask, close: () => { closeSync(w); closeSync(r); child.kill(); rmSync(dir, { recursive: true }); } };
  const [bx, by, bz, t] = option('--field', '0,0,0,25').split(',').map(Number);
  ask(`F ${bx} ${by} ${bz} ${t}`);
  const i2c = mcu.i2c[0];
  const now = () => Math.floor(sim.clock.nanos / 1000);
  let addr = -1, writing = false, wbuf = [], rbuf = [];
  const flush = () => {
    if (addr >= 0 && writing && wbuf.length) ask(`W ${addr} ${now()} ${Buffer.from(wbuf).toString('hex')}`);
    wbuf = [];
  };
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
  const later = (bits, fn) => {
    if (!timed) return fn();
    sim.clock.createAlarm(fn).schedule(bits * (i2c.sclLowPeriod + i2c.sclHighPeriod) * 8); // 8 ns a cycle
  };
  i2c.onStart = () => { flush(); later(1, () => i2c.completeStart()); };
  i2c.onConnect = (address, mode) => {
    flush();
    addr = address;
    writing = mode === 0;
    let present = ask(`A ${address}`) === '1';
    if (present && pending['nack-addr']) {
      pending['nack-addr'] -= 1;
      present = false;
    }
    if (present && !writing) {
      if (pending['all-ff']) {
        pending['all-ff'] -= 1;
        rbuf = new Array(9).fill(0xff);
      } else {
        const [, hex] = ask(`R ${address} ${now()} 9`).split(' ');
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
}

let uart = '', usb = '', usb_hex = '', usb_connected = false;
const done = () => {
  sim.stop();
  if (mlx) mlx.close();
  console.log(JSON.stringify({ boot2_crc_ok, blocks, uart, usb, usb_hex, usb_connected, nanos: sim.clock.nanos }));
  process.exit(0);
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
