#!/usr/bin/python3
"""test_daemon_modbus.py -- the real luxradd with its Modbus server, read
by real clients (mbpoll, pymodbus) while a job runs.

  test_daemon_modbus.py LUXRADD CORNELL_GLTF

Starts luxradd on ephemeral ports (--modbus-listen 127.0.0.1:0) in a
temporary data directory, uploads the Cornell box with two sensor nodes
(one by name, one by extras), solves a job long enough to be read while
it runs, and checks: the addr file's modbus line; iteration and progress
rise between reads (pymodbus and mbpoll); the job reaches "done" in the
registers; each sensor's f32 lux is float32 of the double query.points
returns for the same point, its scaled u16 is round(lux) and its
iteration the job's; a sensor added with sensor.add gets the same
treatment; writes get exception 01; a client sending half a frame does
not delay another client's read; status and /metrics show the server
and its clients; job.delete empties the slots.  Run with Debian's
/usr/bin/python3 (pymodbus).
"""
import json
import math
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time

from pymodbus.client import ModbusTcpClient
from pymodbus.pdu import ExceptionResponse

LUXRADD, CORNELL = sys.argv[1], sys.argv[2]
DEADLINE_S = float(os.environ.get("LUXRAD_TEST_DEADLINE", "120"))


class Failure(Exception):
    pass


def check(cond, what):
    if not cond:
        raise Failure(what)


def wait_for(what, fn, timeout=20.0, every=0.02):
    """Poll fn() until it returns a true value; fail after timeout."""
    end = time.monotonic() + timeout
    while True:
        v = fn()
        if v:
            return v
        if time.monotonic() > end:
            raise Failure("timed out waiting for " + what)
        time.sleep(every)


def f32(x):
    return struct.unpack(">f", struct.pack(">f", x))[0]


def u32(r, i):
    return (r[i] << 16) | r[i + 1]


def fl32(r, i):
    return struct.unpack(">f", struct.pack(">HH", r[i], r[i + 1]))[0]


def name_of(r):
    b = b"".join(struct.pack(">H", x) for x in r)
    return b.rstrip(b"\0").decode()


# ------------------------------------------------------------- the scene

SENSORS = {  # name -> [x, y, z, nx, ny, nz]
    "floor": [0.278, 0.0, 0.2796, 0.0, 1.0, 0.0],
    "corner": [0.1, 0.0, 0.1, 0.0, 1.0, 0.0],
}


def scene_with_sensors():
    d = json.load(open(CORNELL))
    nodes = d["scenes"][d.get("scene", 0)]["nodes"]
    d["nodes"].append({"name": "sensor:floor",
                       "translation": SENSORS["floor"][:3]})
    nodes.append(len(d["nodes"]) - 1)
    d["nodes"].append({"name": "probe", "translation": SENSORS["corner"][:3],
                       "extras": {"luxrad_sensor": "corner"}})
    nodes.append(len(d["nodes"]) - 1)
    return json.dumps(d).encode()


# ----------------------------------------------------- protocol client

class Conn:
    def __init__(self, host, port):
        self.s = socket.create_connection((host, port), timeout=30)
        self.buf = b""
        self.next_id = 1
        r = self.call("hello", version=1)
        check(r.get("ok"), "hello: %s" % r)

    def call(self, cmd, payload=None, **args):
        hdr = dict(args, cmd=cmd, id=self.next_id)
        self.next_id += 1
        if payload is not None:
            hdr["bytes"] = len(payload)
        self.s.sendall(json.dumps(hdr).encode() + b"\n" + (payload or b""))
        while True:
            while b"\n" not in self.buf:
                chunk = self.s.recv(65536)
                check(chunk, "daemon closed the connection")
                self.buf += chunk
            line, self.buf = self.buf.split(b"\n", 1)
            r = json.loads(line)
            n = r.get("bytes", 0)
            while len(self.buf) < n:
                self.buf += self.s.recv(65536)
            self.buf = self.buf[n:]
            if r.get("id") == hdr["id"]:
                return r

    def ok(self, cmd, payload=None, **args):
        r = self.call(cmd, payload, **args)
        check(r.get("ok") is True, "%s: %s" % (cmd, r))
        return r


# --------------------------------------------------------- the daemon

class Daemon:
    def __init__(self, tmp):
        self.dir = os.path.join(tmp, "data")
        os.mkdir(self.dir)
        self.log = open(os.path.join(tmp, "luxradd.log"), "w+")
        self.p = subprocess.Popen(
            [LUXRADD, "--data-dir", self.dir, "--listen-tcp", "127.0.0.1:0",
             "--listen-unix", "none", "--metrics-listen", "127.0.0.1:0",
             "--modbus-listen", "127.0.0.1:0", "--workers", "1",
             "--solver-threads", "1", "--log-level", "debug"],
            stdout=self.log, stderr=subprocess.STDOUT)
        addr = os.path.join(self.dir, "luxradd.addr")

        def lines():
            check(self.p.poll() is None, "luxradd exited: " + self.logtext())
            try:
                t = open(addr).read()
            except FileNotFoundError:
                return None
            return t if "modbus " in t else None
        text = wait_for("luxradd.addr", lines)
        self.addr = dict(l.split(" ", 1) for l in text.splitlines())
        check(re.fullmatch(r"127\.0\.0\.1:\d+", self.addr["modbus"]),
              "modbus line: %r" % text)
        self.mb_port = int(self.addr["modbus"].rsplit(":", 1)[1])
        check(self.mb_port > 0, "modbus port 0 in luxradd.addr")
        h, p = self.addr["tcp"].rsplit(":", 1)
        self.tcp = (h, int(p))
        h, p = self.addr["metrics"].rsplit(":", 1)
        self.metrics = (h, int(p))

    def logtext(self):
        self.log.flush()
        self.log.seek(0)
        return self.log.read()[-4000:]

    def stop(self):
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
            try:
                rc = self.p.wait(30)
            except subprocess.TimeoutExpired:
                self.p.kill()
                raise Failure("luxradd did not stop on SIGTERM")
            check(rc == 0, "luxradd exit status %d" % rc)


def http_get(addr, path):
    s = socket.create_connection(addr, timeout=10)
    s.sendall(("GET %s HTTP/1.0\r\n\r\n" % path).encode())
    out = b""
    while True:
        b = s.recv(65536)
        if not b:
            break
        out += b
    s.close()
    return out.decode()


# ----------------------------------------------------- Modbus clients

def mb_client(port):
    c = ModbusTcpClient("127.0.0.1", port=port, timeout=5)
    check(c.connect(), "pymodbus cannot connect")
    return c


def mb_read(c, addr, n):
    rr = c.read_input_registers(addr, n, slave=1)
    check(not rr.isError(), "read %d+%d: %s" % (addr, n, rr))
    return rr.registers


def mbpoll(port, *args):
    cmd = ["mbpoll", "-m", "tcp", "-p", str(port), "-a", "1", "-0", "-1"]
    cmd += list(args) + ["127.0.0.1"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=20)
    check(r.returncode == 0, "%s: %s %s" % (cmd, r.stdout, r.stderr))
    vals = {}
    for m in re.finditer(r"^\[(\d+)\]:\s+(\S+)", r.stdout, re.M):
        vals[int(m.group(1))] = m.group(2)
    check(vals, "mbpoll printed no value: %s" % r.stdout)
    return vals


def sensor_slots(c, nslots):
    """name -> slot for the occupied sensor slots."""
    out = {}
    for k in range(nslots):
        r = mb_read(c, 3000 + 16 * k, 16)
        if u32(r, 0) != 0:
            out[name_of(r[8:16])] = k
    return out


# ---------------------------------------------------------------- test

def run(tmp):
    d = Daemon(tmp)
    try:
        body(d)
        d.stop()
    finally:
        if d.p.poll() is None:
            d.p.kill()
            d.p.wait()


def body(d):
    conn = Conn(*d.tcp)
    c = mb_client(d.mb_port)
    port = d.mb_port

    # Daemon block before any job: map version, no jobs, float probe.
    r = mb_read(c, 0, 21)
    check(r[0] == 1 and r[1] == 8 and r[2] == 32 and r[3] == 0,
          "daemon block header %s" % r[:4])
    check(fl32(r, 4) == 1.0, "float probe %s" % r[4:6])
    check(sum(r[10:16]) == 0, "jobs counted before any: %s" % r[10:16])

    up = conn.ok("scene.upload", scene_with_sensors(), name="cornell-s")
    scene = up["scene"]
    job = conn.ok("job.create", scene=scene, solver="hr",
                  options={"eps": 2e-5, "tol": 1e-12,
                           "max_iterations": 35})["job"]

    # Created: slot 0 paused, never run; sensors declared without values.
    r = mb_read(c, 1000, 20)
    check(u32(r, 0) == job and r[2] == 3, "job slot at create: %s" % r)
    check(u32(r, 18) == scene, "scene id %d" % u32(r, 18))
    check(r[3] == 0xFFFF, "progress of a job never run: %d" % r[3])
    slots = sensor_slots(c, 32)
    check(set(slots) == set(SENSORS), "sensor slots %s" % slots)
    for name, k in slots.items():
        s = mb_read(c, 3000 + 16 * k, 16)
        check(u32(s, 0) == job and s[6] == 1, "declared %s: %s" % (name, s))
        check(math.isnan(fl32(s, 2)) and s[7] == 0xFFFF,
              "declared %s has a value: %s" % (name, s))

    # A run long enough to be watched.
    # Converge, capped by max_iterations: "done" at 35 (Cornell with this
    # eps converges later), 50..100 ms an iteration.
    conn.ok("job.run", job=job, converge=True)
    wait_for("running", lambda: mb_read(c, 1000, 20)[2] == 2)
    first = wait_for("iteration >= 1",
                     lambda: (lambda r: r if u32(r, 4) >= 1 else None)(
                         mb_read(c, 1000, 20)))
    # pymodbus: iteration and progress go up between reads.
    second = wait_for(
        "iteration and progress to rise",
        lambda: (lambda r: r if u32(r, 4) > u32(first, 4) and
                 r[3] > first[3] else None)(mb_read(c, 1000, 20)),
        timeout=30)
    check(second[2] in (2, 4), "state %d while running" % second[2])
    check(second[3] <= 1000, "progress %d" % second[3])

    # mbpoll: iteration (u32, ABCD) rises too, progress readable.
    it1 = int(mbpoll(port, "-B", "-t", "3:int", "-r", "1004")[1004])
    it2 = wait_for(
        "mbpoll iteration to rise",
        lambda: (lambda v: v if v > it1 else None)(
            int(mbpoll(port, "-B", "-t", "3:int", "-r", "1004")[1004])),
        timeout=30, every=0.05)
    check(it2 > it1, "mbpoll iteration %d -> %d" % (it1, it2))
    v = mbpoll(port, "-t", "3", "-r", "1000", "-c", "20")
    check(int(v[1000]) * 65536 + int(v[1001]) == job, "mbpoll job id %s" % v)

    # A half frame on one connection does not block another client.
    half = socket.create_connection(("127.0.0.1", port), timeout=5)
    half.sendall(b"\x00\x01\x00\x00\x00\x06\x01")  # 7 of 12 bytes
    time.sleep(0.05)
    t0 = time.monotonic()
    mb_read(c, 1000, 20)
    c2 = mb_client(port)
    mb_read(c2, 0, 21)
    dt = time.monotonic() - t0
    check(dt < 0.5, "read behind a half frame took %.3f s" % dt)

    # status shows the server and the clients now connected (c, c2,
    # half: 3).
    def st_ok():
        m = conn.ok("status")["modbus"]
        return m if m["clients"] >= 3 else None
    m = wait_for("status: 3 modbus clients", st_ok, timeout=5)
    check(m["state"] == "listening" and m["port"] == port,
          "status modbus %s" % m)
    check(m["requests"] > 0 and m["accepted"] >= 3, "status modbus %s" % m)
    met = http_get(d.metrics, "/metrics")
    mm = re.search(r"^luxradd_modbus_clients (\d+)$", met, re.M)
    check(mm and int(mm.group(1)) >= 2, "metrics: %s" % (mm and mm.group(0)))
    check(re.search(r"^luxradd_modbus_requests_total \d+$", met, re.M),
          "metrics: no luxradd_modbus_requests_total")
    c2.close()
    half.close()

    # Writes are refused with exception 01 (illegal function).
    rr = c.write_register(10, 5, slave=1)
    check(isinstance(rr, ExceptionResponse) and rr.exception_code == 1,
          "write_register: %s" % rr)
    rr = c.write_registers(1000, [1, 2], slave=1)
    check(isinstance(rr, ExceptionResponse) and rr.exception_code == 1,
          "write_registers: %s" % rr)

    # Done: state 4, progress 1000, eta 0, the iteration asked for.
    r = wait_for("done", lambda: (lambda r: r if r[2] == 4 else None)(
        mb_read(c, 1000, 20)), timeout=DEADLINE_S, every=0.1)
    info = conn.ok("job.info", job=job)["job"]
    check(info["state"] == "done", "job.info %s" % info["state"])
    iters = info["iteration"]
    check(u32(r, 4) == iters and r[3] == 1000 and u32(r, 16) == 0,
          "done slot %s, job.info iteration %d" % (r, iters))
    daemon = mb_read(c, 0, 21)
    check(daemon[13] == 1 and daemon[11] == 0, "jobs by state %s" %
          daemon[10:16])

    # Sensors: the float is float32 of query.points' double, the scaled
    # u16 its rounding, the iteration the job's.
    def sensors_final():
        ok = True
        for name, k in slots.items():
            s = mb_read(c, 3000 + 16 * k, 16)
            ok = ok and s[6] == 2 and u32(s, 4) == iters
        return ok
    wait_for("sensor values of the last iteration", sensors_final)
    for name, k in slots.items():
        s = mb_read(c, 3000 + 16 * k, 16)
        q = conn.ok("query.points", job=job, points=[SENSORS[name]])
        lux = q["lux"][0]
        check(lux > 0, "%s: lux %s" % (name, lux))
        check(fl32(s, 2) == f32(lux),
              "%s: register %r, query.points %r" % (name, fl32(s, 2), lux))
        check(s[7] == min(65534, round(lux)),
              "%s: scaled %d, lux %r" % (name, s[7], lux))
        v = mbpoll(port, "-B", "-t", "3:float", "-r", str(3002 + 16 * k))
        got = float(v[3002 + 16 * k])
        check(abs(got - lux) <= 1e-5 * abs(lux),
              "%s: mbpoll %r vs %r" % (name, got, lux))
        sl = conn.ok("sensor.list", job=job)["sensors"]
        e = [x for x in sl if x["name"] == name]
        check(e and e[0]["lux"] == lux and e[0]["slot"] == k and
              e[0]["source"] == "scene", "sensor.list %s" % sl)

    # sensor.add on the done job: evaluated on its solution at once.
    desk = [0.2, 0.0, 0.35, 0.0, 1.0, 0.0]
    a = conn.ok("sensor.add", job=job, name="desk", point=desk)
    k = a["slot"]
    check(isinstance(k, int) and k not in slots.values(), "slot %s" % a)
    r = conn.call("sensor.add", job=job, name="desk", point=desk)
    check(r.get("ok") is False and r["error"]["code"] == "state",
          "duplicate sensor.add: %s" % r)
    s = wait_for("desk value", lambda: (lambda s: s if s[6] == 2 else None)(
        mb_read(c, 3000 + 16 * k, 16)))
    q = conn.ok("query.points", job=job, points=[desk])["lux"][0]
    check(name_of(s[8:16]) == "desk" and u32(s, 4) == iters,
          "desk slot %s" % s)
    check(fl32(s, 2) == f32(q), "desk %r vs %r" % (fl32(s, 2), q))

    # job.delete empties the job slot and the sensor slots.
    conn.ok("job.delete", job=job)
    r = mb_read(c, 1000, 20)
    check(u32(r, 0) == 0 and r[2] == 0, "deleted job's slot %s" % r)
    check(sensor_slots(c, 32) == {}, "sensors left after job.delete")
    c.close()


def main():
    tmp = tempfile.mkdtemp(prefix="luxrad-mbd-")
    try:
        run(tmp)
    except Exception as e:  # pylint: disable=broad-except
        log = os.path.join(tmp, "luxradd.log")
        print("FAIL:", e)
        if os.path.exists(log):
            print("--- luxradd log (tail) ---")
            print(open(log).read()[-6000:])
        return 1
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print("ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
