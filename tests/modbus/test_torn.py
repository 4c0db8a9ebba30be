#!/usr/bin/python3
"""test_torn.py -- no torn 32-bit values under concurrent publication.

  test_torn.py MB_TESTSERVER MB_TORNREAD

mb_testserver --mode torn flips three 32-bit values between two patterns
whose words both differ, as fast as it can, while mb_tornread (libmodbus)
and a pymodbus client read them over and over; any pair mixing the words
of the two patterns is a torn update.  Both patterns must be seen, else
the run proved nothing.  ABCD with 20000 libmodbus reads, then CDAB.
"""
import subprocess
import sys
import threading

from pymodbus.client import ModbusTcpClient

from mbtest import Failure, Server, check, u32

EXE, READER = sys.argv[1], sys.argv[2]
PATTERNS = {"iteration": (0x0000FFFF, 0x00010000),
            "residual": (0x3F800000, 0x40490FDB),
            "lux": (0x3F800000, 0x40490FDB)}


def pymodbus_reader(port, order, stop, out):
    c = ModbusTcpClient("127.0.0.1", port=port, timeout=2)
    c.connect()
    seen = {k: [0, 0] for k in PATTERNS}
    torn = []
    while not stop.is_set():
        a = c.read_input_registers(1004, 4, slave=1)
        b = c.read_input_registers(3002, 2, slave=1)
        if a.isError() or b.isError():
            torn.append("read error")
            break
        vals = {"iteration": u32(a.registers, 0, order),
                "residual": u32(a.registers, 2, order),
                "lux": u32(b.registers, 0, order)}
        for k, v in vals.items():
            if v in PATTERNS[k]:
                seen[k][PATTERNS[k].index(v)] += 1
            else:
                torn.append("%s 0x%08x" % (k, v))
    c.close()
    out["seen"], out["torn"] = seen, torn


def run(order, reads):
    with Server(EXE, "modbus_word_order=" + order, mode="torn") as s:
        stop, out = threading.Event(), {}
        th = threading.Thread(target=pymodbus_reader,
                              args=(s.port, order, stop, out))
        th.start()
        p = subprocess.run([READER, str(s.port), str(reads), order],
                           capture_output=True, text=True, timeout=300)
        stop.set()
        th.join()
        print("%s libmodbus: %s%s" % (order, p.stdout, p.stderr), end="")
        print("%s pymodbus: %s, torn %d" % (order, out["seen"],
                                            len(out["torn"])))
        check(p.returncode == 0, "mb_tornread failed (%s)" % order)
        check(not out["torn"], "pymodbus saw %s" % out["torn"][:5])
        check(all(a and b for a, b in out["seen"].values()),
              "pymodbus did not see both patterns: %s" % out["seen"])


def main():
    try:
        run("abcd", 20000)
        run("cdab", 5000)
    except Failure as e:
        print("FAIL:", e)
        return 1
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
