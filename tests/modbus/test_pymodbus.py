#!/usr/bin/python3
"""test_pymodbus.py -- pymodbus (a second real client) and raw sockets
against mb_testserver.

  test_pymodbus.py MB_TESTSERVER

Checks: every block decodes to what was published (ABCD and CDAB);
iteration and progress rise and the job reaches "done"; each write and
each unsupported read gets exception 01, out-of-range reads 02, bad
quantities and lengths 03, a foreign unit id 0B; raw frames: unknown
function codes, transaction ids echoed, pipelined and byte-by-byte
requests, non-Modbus frames closed; half frames, idle clients, clients
past the limit, and a client that never reads its responses are closed
without delaying anyone else; 40 clients at once are all served.
"""
import concurrent.futures
import socket
import struct
import sys
import threading
import time

from pymodbus.client import ModbusTcpClient
from pymodbus.pdu import ExceptionResponse

from mbtest import (Failure, Server, check, closed_by_peer, connect,
                    expect_daemon, expect_job7, expect_jobs_static,
                    expect_sensor, mbap, read_pdu, recv_frame, u32)

EXE = sys.argv[1]


def client(port):
    c = ModbusTcpClient("127.0.0.1", port=port, timeout=2)
    check(c.connect(), "pymodbus cannot connect")
    return c


def read(c, addr, count, slave=1):
    rr = c.read_input_registers(addr, count, slave=slave)
    check(not rr.isError(), "read %d+%d: %s" % (addr, count, rr))
    return rr.registers


def exception(rr, fc, code):
    check(isinstance(rr, ExceptionResponse) and rr.isError(),
          "expected an exception for fc %d, got %s" % (fc, rr))
    check(rr.function_code == fc | 0x80 and rr.exception_code == code,
          "fc %d: exception %d/%d, expected %d/%d" %
          (fc, rr.function_code, rr.exception_code, fc | 0x80, code))


def test_blocks():
    for order in ("abcd", "cdab"):
        with Server(EXE, "modbus_word_order=" + order) as s:
            c = client(s.port)
            expect_daemon(read(c, 0, 21), order)
            it1, p1 = expect_job7(read(c, 1000, 20), order)
            time.sleep(0.3)
            it2, p2 = expect_job7(read(c, 1000, 20), order)
            check(it2 > it1 and p2 > p1, "no progress %d -> %d" % (it1, it2))
            expect_jobs_static(read(c, 1020, 120), order)
            sens = read(c, 3000, 80)
            for k in range(5):
                expect_sensor(k, sens[16 * k:16 * k + 16], order)
            c.close()


def test_reaches_done():
    extra = ("--done-after", "40", "--tick-ms", "20")
    with Server(EXE, extra=extra) as s:
        c = client(s.port)
        deadline = time.monotonic() + 10
        seen = []
        while time.monotonic() < deadline:
            r = read(c, 1000, 20)
            seen.append((r[2], u32(r, 4, "abcd"), r[3]))
            if r[2] == 4:
                break
            time.sleep(0.05)
        check(seen[-1] == (4, 40, 1000), "job 7 not done: %s" % seen[-3:])
        check(all(a[1] <= b[1] for a, b in zip(seen, seen[1:])),
              "iteration went down: %s" % seen)
        r = read(c, 1000, 20)
        check(u32(r, 16, "abcd") == 0, "eta of a done job")
        d = read(c, 10, 6)
        check(d == [0, 0, 1, 2, 0, 0], "jobs by state when done: %s" % d)
        c.close()


def test_exceptions():
    with Server(EXE) as s:
        c = client(s.port)
        before = read(c, 1020, 40)
        exception(c.write_register(10, 5, slave=1), 6, 1)
        exception(c.write_registers(10, [1, 2], slave=1), 16, 1)
        exception(c.write_coil(1, True, slave=1), 5, 1)
        exception(c.write_coils(1, [True, False], slave=1), 15, 1)
        exception(c.mask_write_register(1, 0, 0, slave=1), 22, 1)
        exception(c.readwrite_registers(read_address=0, read_count=1,
                                        write_address=1,
                                        write_registers=[1], slave=1),
                  23, 1)
        exception(c.read_holding_registers(0, 1, slave=1), 3, 1)
        exception(c.read_coils(0, 1, slave=1), 1, 1)
        exception(c.read_discrete_inputs(0, 1, slave=1), 2, 1)
        for addr, n in ((21, 1), (0, 22), (999, 2), (1160, 1), (3512, 1),
                        (20, 2), (65535, 1)):
            exception(c.read_input_registers(addr, n, slave=1), 4, 2)
        exception(c.read_input_registers(0, 1, slave=9), 4, 11)
        check(read(c, 0, 1, slave=255) == [1], "unit 255")
        check(read(c, 0, 1, slave=0) == [1], "unit 0")
        check(read(c, 1020, 40) == before, "a write changed the map")
        c.close()


def raw(sock, frame):
    sock.sendall(frame)
    r = recv_frame(sock)
    check(r, "no answer to %s" % frame.hex())
    return r


def test_raw_frames():
    with Server(EXE) as s:
        a = connect(s.port)
        for fc in (0x41, 0x2B, 0x07, 0x08, 0x11, 0x18, 0x7F, 0x80, 0xFF):
            r = raw(a, mbap(0x1234, 1, bytes([fc]) + b"\0\0"))
            check(r[:2] == b"\x12\x34" and r[7] == (fc | 0x80) & 0xFF and
                  r[8] == 1, "fc 0x%02x: %s" % (fc, r.hex()))
        for pdu, code in ((read_pdu(0, 0), 3), (read_pdu(0, 126), 3),
                          (read_pdu(60000, 126), 3),  # quantity first
                          (read_pdu(0, 1) + b"\0", 3), (b"\x04\0\0\0", 3),
                          (read_pdu(21, 1), 2)):
            r = raw(a, mbap(7, 1, pdu))
            check(r[7] == 0x84 and r[8] == code,
                  "%s -> %s, expected %d" % (pdu.hex(), r.hex(), code))
        r = raw(a, mbap(8, 1, read_pdu(0, 21)))
        check(r[7] == 4 and r[8] == 42, "21 registers: %s" % r.hex())
        # pipelined: three requests in one segment, answered in order
        a.sendall(b"".join(mbap(100 + k, 1, read_pdu(k, 1))
                           for k in range(3)))
        for k in range(3):
            r = recv_frame(a)
            check(struct.unpack(">H", r[:2])[0] == 100 + k,
                  "pipelined answer %d: %s" % (k, r.hex()))
        # byte by byte, slower than any sane client
        for byte in mbap(200, 1, read_pdu(0, 1)):
            a.sendall(bytes([byte]))
            time.sleep(0.02)
        r = recv_frame(a)
        check(r[:2] == b"\x00\xc8" and r[9:11] == b"\x00\x01",
              "byte-by-byte request: %s" % r.hex())
        a.close()
        for frame in (mbap(1, 1, read_pdu(0, 1), proto=1),
                      mbap(1, 1, read_pdu(0, 1), length=255),
                      mbap(1, 1, b"", length=1)):
            b = connect(s.port)
            b.sendall(frame)
            check(closed_by_peer(b, 2), "not closed: %s" % frame.hex())
            b.close()


def timed_read(port):
    c = client(port)
    t0 = time.monotonic()
    r = read(c, 0, 21)
    took = time.monotonic() - t0
    c.close()
    return r, took


def test_half_frames():
    with Server(EXE, "modbus_frame_timeout=1s") as s:
        held = [connect(s.port) for _ in range(3)]
        held[0].sendall(mbap(1, 1, read_pdu(0, 1))[:3])
        held[1].sendall(mbap(1, 1, read_pdu(0, 1))[:7])
        held[2].sendall(mbap(1, 1, read_pdu(0, 1))[:11])
        t0 = time.monotonic()
        for _ in range(5):
            r, took = timed_read(s.port)
            check(r[0] == 1 and took < 0.5, "read beside half frames "
                  "took %.2f s" % took)
        check(time.monotonic() - t0 < 1.0, "reads beside half frames slow")
        for h in held:
            check(closed_by_peer(h, 3), "half frame not closed")
            h.close()


def test_idle_timeout():
    with Server(EXE, "modbus_idle_timeout=1s") as s:
        a = connect(s.port)
        r = raw(a, mbap(1, 1, read_pdu(0, 1)))
        check(r[7] == 4, "first read")
        t0 = time.monotonic()
        check(closed_by_peer(a, 3), "idle client not closed")
        took = time.monotonic() - t0
        check(0.8 < took < 2.5, "closed after %.2f s, idle timeout 1 s" %
              took)
        a.close()


def test_max_clients():
    with Server(EXE, "modbus_max_clients=4") as s:
        socks = [connect(s.port) for _ in range(4)]
        for k, sk in enumerate(socks):
            check(raw(sk, mbap(k, 1, read_pdu(20, 1)))[7] == 4, "client %d" % k)
        extra = connect(s.port)
        check(closed_by_peer(extra, 2), "fifth client not closed")
        extra.close()
        socks.pop().close()
        deadline, ok = time.monotonic() + 3, False
        while not ok and time.monotonic() < deadline:
            sk = connect(s.port)
            try:
                sk.sendall(mbap(9, 1, read_pdu(20, 1)))
                ok = bool(recv_frame(sk, 0.5))
            except OSError:
                ok = False
            if ok:
                socks.append(sk)
            else:
                sk.close()
                time.sleep(0.05)
        check(ok, "no room after a client left")
        r = raw(socks[0], mbap(1, 1, read_pdu(20, 1)))
        check(r[9:11] == b"\x00\x04", "client count register: %s" % r.hex())
        for sk in socks:
            sk.close()


def test_non_reader():
    """A client that pipelines requests and never reads the answers is
    closed -- when a response no longer fits its socket, or, if TCP stalls
    first (the client's full receive buffer also holds back the acks of
    its own data), by the idle timeout -- and never delays the others."""
    with Server(EXE, "modbus_idle_timeout=2s") as s:
        hog = connect(s.port)
        frame = mbap(1, 1, read_pdu(3000, 80))
        stop = threading.Event()
        result = {}

        def flood():
            try:
                hog.settimeout(10)
                while not stop.is_set():
                    hog.sendall(frame * 256)
            except OSError as e:
                result["closed"] = e

        th = threading.Thread(target=flood)
        th.start()
        worst = 0
        for _ in range(20):
            r, took = timed_read(s.port)
            worst = max(worst, took)
            time.sleep(0.05)
        th.join(8)
        stop.set()
        check(worst < 0.5, "reads beside a flooding client took %.2f s" %
              worst)
        check(not isinstance(result.get("closed"), socket.timeout) and
              "closed" in result, "the non-reading client was not closed: "
              "%r" % result.get("closed"))
        hog.close()
        th.join()
        log = s.stop()
        check("response not sent" in log or "(idle)" in log,
              "close reason not logged")


def test_many_clients():
    with Server(EXE, "modbus_max_clients=64") as s:
        def one(_):
            c = client(s.port)
            for _ in range(50):
                expect_job7(read(c, 1000, 20), "abcd")
            c.close()
            return True

        with concurrent.futures.ThreadPoolExecutor(40) as pool:
            check(all(pool.map(one, range(40))), "a client failed")


def main():
    tests = [test_blocks, test_reaches_done, test_exceptions, test_raw_frames,
             test_half_frames, test_idle_timeout, test_max_clients,
             test_non_reader, test_many_clients]
    failed = 0
    for t in tests:
        t0 = time.monotonic()
        try:
            t()
            print("PASS %s (%.1f s)" % (t.__name__, time.monotonic() - t0))
        except (Failure, OSError, KeyError, IndexError, struct.error) as e:
            failed += 1
            print("FAIL %s: %s: %s" % (t.__name__, type(e).__name__, e))
    print("%d of %d failed" % (failed, len(tests)))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
