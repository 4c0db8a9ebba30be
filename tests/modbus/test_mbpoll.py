#!/usr/bin/python3
"""test_mbpoll.py -- mbpoll, a real Modbus client, against mb_testserver.

  test_mbpoll.py MB_TESTSERVER MODBUS_MD

Checks: every mbpoll command line of MODBUS.md's examples runs and reads
(port 1502 replaced by the test server's); each block read with mbpoll
matches what the server published, in ABCD (-B) and, on a CDAB server, in
mbpoll's default CDAB; iteration and progress rise between two reads;
writes, holding/coil reads, out-of-range reads and a foreign unit id get
the documented exception (mbpoll exits 1); a client holding half a frame
does not delay mbpoll; many mbpoll processes at once are all served.
"""
import concurrent.futures
import re
import shlex
import subprocess
import sys
import time

from mbtest import (SENSORS, Failure, Server, check, closed_by_peer, connect,
                    expect_daemon, expect_job7, expect_jobs_static,
                    expect_sensor, f32, fl32, mbap, read_pdu, text, u32)

EXE, DOC = sys.argv[1], sys.argv[2]


def mbpoll(port, *args, values=(), timeout=10):
    """Run mbpoll once (values: to write, after the host, as mbpoll wants
    them); (exit code, {reference: first token}, output)."""
    cmd = ["mbpoll", "-m", "tcp", "-p", str(port), "-1", *args, "127.0.0.1",
           *values]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    vals = {int(m.group(1)): m.group(2)
            for m in re.finditer(r"^\[(\d+)\]:\s+(\S+)", p.stdout, re.M)}
    return p.returncode, vals, p.stdout + p.stderr


def regs(port, addr, count, *extra):
    """count 16-bit input registers from addr, as a list."""
    rc, vals, out = mbpoll(port, "-0", "-t", "3", "-r", str(addr), "-c",
                           str(count), *extra)
    check(rc == 0, "mbpoll read %d+%d failed: %s" % (addr, count, out))
    return [int(vals[addr + i]) for i in range(count)]


def doc_commands():
    """The mbpoll lines of MODBUS.md's example block."""
    with open(DOC) as f:
        doc = f.read()
    m = re.search(r"<!-- mbpoll examples.*?-->\s*```sh\n(.*?)```", doc, re.S)
    check(m, "MODBUS.md has no mbpoll example block")
    return [l for l in m.group(1).splitlines() if l.startswith("mbpoll ")]


def test_doc_commands():
    cmds = doc_commands()
    check(len(cmds) >= 6, "only %d mbpoll examples" % len(cmds))
    blocks = set()
    with Server(EXE) as s:
        for line in cmds:
            check(" -p 1502 " in line, "example without -p 1502: " + line)
            argv = shlex.split(line.replace(" -p 1502 ", " -p %d " % s.port))
            p = subprocess.run(argv, capture_output=True, text=True,
                               timeout=10)
            refs = [int(r) for r in re.findall(r"^\[(\d+)\]:", p.stdout,
                                               re.M)]
            check(p.returncode == 0 and refs,
                  "documented command failed: %s\n%s%s" %
                  (line, p.stdout, p.stderr))
            blocks |= {0 if r < 1000 else 1 if r < 3000 else 2 for r in refs}
    check(blocks == {0, 1, 2}, "examples do not read every block")


def test_abcd():
    with Server(EXE) as s:
        expect_daemon(regs(s.port, 0, 21), "abcd")
        rc, v, out = mbpoll(s.port, "-0", "-B", "-t", "3:float", "-r", "4",
                            "-c", "2")
        check(rc == 0 and v[4] == "1" and v[6] == "1",
              "float probe / lux scale with -B: " + out)
        rc, v, out = mbpoll(s.port, "-0", "-t", "3:float", "-r", "4")
        check(rc == 0 and v[4] != "1", "CDAB view of an ABCD float is 1")
        it1, p1 = expect_job7(regs(s.port, 1000, 20), "abcd")
        time.sleep(0.4)
        it2, p2 = expect_job7(regs(s.port, 1000, 20), "abcd")
        check(it2 > it1 and p2 > p1,
              "iteration/progress did not rise: %d/%d -> %d/%d" %
              (it1, p1, it2, p2))
        rc, v, out = mbpoll(s.port, "-0", "-B", "-t", "3:int", "-r", "1004")
        check(rc == 0 and int(v[1004]) >= it2, "iteration as 3:int: " + out)
        expect_jobs_static(regs(s.port, 1020, 120), "abcd")
        sens = regs(s.port, 3000, 16 * 6)
        for k in range(5):
            expect_sensor(k, sens[16 * k:16 * k + 16], "abcd")
        e = sens[80:96]
        check(u32(e, 0, "abcd") == 0 and e[6] == 0 and text(e[8:]) == "",
              "sensor slot 5 not empty")
        for slot, (_, name, lux, _, _, _) in enumerate(SENSORS):
            if lux is None:
                continue
            r = 3000 + 16 * slot + 2
            rc, v, out = mbpoll(s.port, "-0", "-B", "-t", "3:float", "-r",
                                str(r))
            want = "%g" % f32(lux)
            check(rc == 0 and v[r] == want,
                  "sensor %s as 3:float: %r, expected %r" %
                  (name, v.get(r), want))


def test_cdab():
    with Server(EXE, "modbus_word_order=cdab") as s:
        expect_daemon(regs(s.port, 0, 21), "cdab")
        rc, v, out = mbpoll(s.port, "-0", "-t", "3:float", "-r", "4", "-c",
                            "2")
        check(rc == 0 and v[4] == "1" and v[6] == "1",
              "float probe / lux scale, CDAB: " + out)
        rc, v, out = mbpoll(s.port, "-0", "-B", "-t", "3:float", "-r", "4")
        check(rc == 0 and v[4] != "1", "ABCD view of a CDAB float is 1")
        expect_job7(regs(s.port, 1000, 20), "cdab")
        expect_jobs_static(regs(s.port, 1020, 120), "cdab")
        sens = regs(s.port, 3000, 80)
        for k in range(5):
            expect_sensor(k, sens[16 * k:16 * k + 16], "cdab")
        rc, v, out = mbpoll(s.port, "-0", "-t", "3:float", "-r", "3002")
        check(rc == 0 and v[3002] == "%g" % f32(123.456), "desk, CDAB")
        rc, v, out = mbpoll(s.port, "-0", "-t", "3:int", "-r", "1020")
        check(rc == 0 and v[1020] == "9", "job 9 id as 3:int, CDAB: " + out)


ERRORS = [  # mbpoll arguments, values written, what libmodbus prints
    (["-t", "4", "-r", "10"], ["5"], "Illegal function"),  # fc 6
    (["-t", "4", "-r", "10"], ["5", "6"], "Illegal function"),  # fc 16
    (["-t", "0", "-r", "10"], ["1"], "Illegal function"),  # fc 5
    (["-t", "0", "-r", "10"], ["1", "0"], "Illegal function"),  # fc 15
    (["-t", "4", "-r", "0"], [], "Illegal function"),  # fc 3
    (["-t", "0", "-r", "0"], [], "Illegal function"),  # fc 1
    (["-t", "1", "-r", "0"], [], "Illegal function"),  # fc 2
    (["-t", "3", "-r", "21"], [], "Illegal data address"),
    (["-t", "3", "-r", "0", "-c", "22"], [], "Illegal data address"),
    (["-t", "3", "-r", "999", "-c", "2"], [], "Illegal data address"),
    (["-t", "3", "-r", "1160"], [], "Illegal data address"),  # slot 8 of 8
    (["-t", "3", "-r", "3512"], [], "Illegal data address"),  # sensor 32
    (["-t", "3", "-r", "65535"], [], "Illegal data address"),
    (["-a", "2", "-t", "3", "-r", "0"], [], "Target device failed to respond"),
]


def test_exceptions():
    with Server(EXE) as s:
        before = regs(s.port, 0, 20)
        for args, values, msg in ERRORS:
            rc, _, out = mbpoll(s.port, "-0", *args, values=values)
            check(rc != 0 and msg in out,
                  "mbpoll %s %s: rc %d, expected '%s':\n%s" %
                  (" ".join(args), " ".join(values), rc, msg, out))
        for unit in ("255", "0", "1"):
            rc, v, out = mbpoll(s.port, "-0", "-a", unit, "-t", "3", "-r",
                                "0")
            check(rc == 0 and v[0] == "1", "unit %s not answered" % unit)
        after = regs(s.port, 0, 20)
        check(before[:8] == after[:8] and before[10:] == after[10:],
              "the daemon block changed after writes")


def test_half_frame():
    with Server(EXE, "modbus_frame_timeout=1s") as s:
        a, b = connect(s.port), connect(s.port)
        a.sendall(mbap(1, 1, read_pdu(0, 1))[:3])
        b.sendall(mbap(2, 1, read_pdu(0, 1))[:9])  # header + part of PDU
        t0 = time.monotonic()
        rc, v, out = mbpoll(s.port, "-0", "-t", "3", "-r", "0", "-o", "1")
        took = time.monotonic() - t0
        check(rc == 0 and v[0] == "1" and took < 1.0,
              "mbpoll beside half frames: rc %d in %.2f s" % (rc, took))
        check(closed_by_peer(a, 3) and closed_by_peer(b, 3),
              "half-frame clients not closed after modbus_frame_timeout")
        a.close()
        b.close()


def test_many_mbpoll():
    with Server(EXE, "modbus_max_clients=64") as s:
        def one(_):
            return mbpoll(s.port, "-0", "-B", "-t", "3:float", "-r", "3002")

        with concurrent.futures.ThreadPoolExecutor(24) as pool:
            res = list(pool.map(one, range(48)))
        bad = [out for rc, v, out in res if rc != 0 or v.get(3002) != "123.456"]
        check(not bad, "%d of 48 concurrent mbpoll failed: %s" %
              (len(bad), bad[:1]))


def main():
    tests = [test_doc_commands, test_abcd, test_cdab, test_exceptions,
             test_half_frame, test_many_mbpoll]
    failed = 0
    for t in tests:
        t0 = time.monotonic()
        try:
            t()
            print("PASS %s (%.1f s)" % (t.__name__, time.monotonic() - t0))
        except (Failure, KeyError, ValueError, OSError,
                subprocess.TimeoutExpired) as e:
            failed += 1
            print("FAIL %s: %s: %s" % (t.__name__, type(e).__name__, e))
    print("%d of %d failed" % (failed, len(tests)))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
