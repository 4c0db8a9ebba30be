"""mbtest.py -- shared helpers of the Modbus tests: start and stop
mb_testserver, decode registers independently of the C encoders (struct),
and the image mb_testserver publishes (the numbers in its header comment).

Run the tests with /usr/bin/python3: Debian's python3-pymodbus is installed
for that interpreter only (docs/PITFALLS.md).
"""
import math
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time

U16_NA = 0xFFFF
U32_NA = 0xFFFFFFFF

# Addresses (MODBUS.md); the tests restate them rather than import them.
JOB_BASE, JOB_STRIDE = 1000, 20
SENSOR_BASE, SENSOR_STRIDE = 3000, 16
DONE_AFTER = 400  # mb_testserver's default --done-after


def f32(x):
    """x rounded to binary32, as a Python float."""
    return struct.unpack(">f", struct.pack(">f", x))[0]


def u32(regs, i, order):
    hi, lo = (regs[i], regs[i + 1]) if order == "abcd" else (regs[i + 1], regs[i])
    return hi << 16 | lo


def fl32(regs, i, order):
    return struct.unpack(">f", struct.pack(">I", u32(regs, i, order)))[0]


def text(regs):
    b = b"".join(struct.pack(">H", r) for r in regs)
    return b.rstrip(b"\0").decode("ascii")


def same_float(a, b):
    return (math.isnan(a) and math.isnan(b)) or a == b


class Failure(Exception):
    pass


def check(cond, what):
    if not cond:
        raise Failure(what)


class Server:
    """An mb_testserver process; use as a context manager."""

    def __init__(self, exe, *sets, mode="normal", extra=()):
        self.dir = tempfile.TemporaryDirectory(prefix="mbtest-")
        self.port_file = os.path.join(self.dir.name, "port")
        args = [exe, "--port-file", self.port_file, "--mode", mode, "--log"]
        for s in sets:
            args += ["--set", s]
        args += list(extra)
        self.log = open(os.path.join(self.dir.name, "log"), "w+")
        self.proc = subprocess.Popen(args, stderr=self.log)
        deadline = time.monotonic() + 10
        while not os.path.exists(self.port_file):
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise Failure("mb_testserver did not start: " + self.log_text())
            time.sleep(0.02)
        with open(self.port_file) as f:
            self.port = int(f.read())

    def log_text(self):
        self.log.flush()
        self.log.seek(0)
        return self.log.read()

    def stop(self):
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                raise Failure("mb_testserver did not stop on SIGTERM")
        check(self.proc.returncode == 0,
              "mb_testserver exited %d" % self.proc.returncode)
        return self.log_text()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        try:
            log = self.stop()
            if exc[0] is not None:
                sys.stderr.write(log)
        finally:
            self.dir.cleanup()


# ----------------------------------------------------------- raw requests

def mbap(tid, unit, pdu, proto=0, length=None):
    n = len(pdu) + 1 if length is None else length
    return struct.pack(">HHHB", tid, proto, n, unit) + pdu


def read_pdu(addr, count, fc=4):
    return struct.pack(">BHH", fc, addr, count)


def recv_exact(sock, n):
    buf = b""
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            return b""
        buf += chunk
    return buf


def recv_frame(sock, timeout=2.0):
    """One response frame (MBAP + PDU), or b'' if the server closed.
    Reads exactly one frame: pipelined responses stay in the socket."""
    sock.settimeout(timeout)
    head = recv_exact(sock, 6)
    if not head:
        return b""
    body = recv_exact(sock, struct.unpack(">H", head[4:6])[0])
    return head + body if body else b""


def connect(port):
    s = socket.create_connection(("127.0.0.1", port), timeout=2)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s


def closed_by_peer(sock, within):
    """True if the server closes sock within `within` seconds."""
    sock.settimeout(within)
    try:
        return sock.recv(16) == b""
    except ConnectionResetError:
        return True
    except socket.timeout:
        return False


# ------------------------------------------- the image mb_testserver shows

def expect_daemon(regs, order):
    """Check registers 0..20 against the published daemon block."""
    check(regs[0] == 1, "map version %d" % regs[0])
    check(regs[1:3] == [8, 32], "slots %s" % regs[1:3])
    check(regs[3] == (0 if order == "abcd" else 1), "word order %d" % regs[3])
    check(fl32(regs, 4, order) == 1.0, "float probe")
    check(fl32(regs, 6, order) == 1.0, "lux scale")
    up = u32(regs, 8, order)
    check(3600 <= up <= 3800, "uptime %d" % up)
    # queued running paused done failed cancelled (job 7 may be done)
    check(regs[10] == 0 and regs[12] == 1 and regs[14:16] == [0, 0],
          "jobs by state %s" % regs[10:16])
    check(regs[11] + regs[13] == 2, "running + done %s" % regs[10:16])
    check(regs[16:18] == [0, 0], "unslotted %s" % regs[16:18])
    check(u32(regs, 18, order) == (123456789 + 1023) // 1024, "memory KiB")
    check(1 <= regs[20] <= 64, "clients %d" % regs[20])


def expect_job7(r, order):
    """Slot 0, job 7, from one 20-register read: every derived value must
    match the iteration of the same snapshot."""
    it = u32(r, 4, order)
    check(1 <= it <= DONE_AFTER, "job 7 iteration %d" % it)
    state = 4 if it >= DONE_AFTER else 2
    check(u32(r, 0, order) == 7 and r[2] == state,
          "job 7 id/state %d/%d at %d" % (u32(r, 0, order), r[2], it))
    check(r[3] == math.floor(it * 1000 / DONE_AFTER + 0.5),
          "progress %d at iteration %d" % (r[3], it))
    check(fl32(r, 6, order) == f32(1.0 / it), "residual at %d" % it)
    check(fl32(r, 8, order) == f32(0.5 / it), "error estimate at %d" % it)
    check(u32(r, 10, order) == 1000 * it, "links at %d" % it)
    check(u32(r, 12, order) == 10240, "memory KiB")
    check(u32(r, 14, order) == math.floor(0.05 * it + 0.5), "elapsed")
    check(u32(r, 16, order) == math.floor(0.05 * (DONE_AFTER - it) + 0.5),
          "eta")
    check(u32(r, 18, order) == 3, "scene id")
    return it, r[3]


def expect_jobs_static(r, order):
    """Slots 1.. (registers 1020.. as one list): job 9, job 12, empties."""
    j9, j12 = r[0:20], r[20:40]
    check([u32(j9, 0, order), j9[2], j9[3], u32(j9, 4, order)] ==
          [9, 4, 1000, 42], "job 9 head %s" % j9[:6])
    check(fl32(j9, 6, order) == 0.015625 and fl32(j9, 8, order) == 0.25,
          "job 9 floats")
    check([u32(j9, k, order) for k in (10, 12, 14, 16, 18)] ==
          [123456, 5120, 12, 0, 3], "job 9 counters")
    check(u32(j12, 0, order) == 12 and j12[2] == 3, "job 12 id/state")
    check(j12[3] == U16_NA and u32(j12, 4, order) == U32_NA,
          "job 12 progress/iteration sentinels")
    check(math.isnan(fl32(j12, 6, order)) and math.isnan(fl32(j12, 8, order)),
          "job 12 float sentinels (NaN)")
    check(all(u32(j12, k, order) == U32_NA for k in (10, 12, 14, 16, 18)),
          "job 12 u32 sentinels")
    for k in range(2, len(r) // 20):
        e = r[20 * k:20 * k + 20]
        check(u32(e, 0, order) == 0 and e[2] == 0, "slot %d empty" % (k + 1))
        check(e[3] == U16_NA and math.isnan(fl32(e, 6, order)),
              "slot %d sentinels" % (k + 1))


SENSORS = [  # slot: (job, name, lux, iteration, status, scaled)
    (7, "desk", 123.456, 1, 2, 123),
    (7, "floor", 0.5, 1, 2, 1),
    (7, "ramp", None, None, 2, None),  # 1.5 x iteration
    (9, "window", 70000.25, 42, 2, 65534),
    (12, "corner", float("nan"), U32_NA, 1, U16_NA),
]


def expect_sensor(slot, r, order):
    job, name, lux, it, status, scaled = SENSORS[slot]
    check(u32(r, 0, order) == job and text(r[8:16]) == name,
          "sensor %d job/name %d %r" % (slot, u32(r, 0, order), text(r[8:16])))
    got_it = u32(r, 4, order)
    if lux is None:  # ramp: consistent with its own iteration
        lux, it, scaled = 1.5 * got_it, got_it, math.floor(1.5 * got_it + 0.5)
    check(same_float(fl32(r, 2, order), f32(lux)),
          "sensor %s lux %r, expected %r" % (name, fl32(r, 2, order), f32(lux)))
    check(got_it == it and r[6] == status and r[7] == scaled,
          "sensor %s iteration/status/scaled %d/%d/%d" % (name, got_it, r[6], r[7]))
