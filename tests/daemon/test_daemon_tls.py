#!/usr/bin/python3
"""test_daemon_tls.py -- the real luxradd speaking TLS, to real TLS
clients: Python's ssl module, openssl s_client and the luxrad client.

  test_daemon_tls.py LUXRADD LUXRAD CORNELL_GLTF

Makes a certificate authority and a server certificate for 127.0.0.1 and
localhost with the openssl command, then checks:
  - a daemon told to listen beyond loopback (tls = auto) without a
    certificate refuses to start, naming tls_cert_file;
  - with --tls all: Python's ssl client verifies the certificate against
    the CA, says hello with a user's token and gets status, over TLS 1.2
    or later; a client trusting another CA fails verification;
    openssl s_client verifies it too;
  - a plain protocol client on the TLS port is told, in plain text, that
    the listener speaks TLS;
  - luxrad --connect tls://... uploads, solves and queries; without the
    CA it fails with exit status 3;
  - a connection over the limit gets its too_many_connections frame
    inside TLS;
  - SIGHUP loads a renewed certificate: new connections verify against
    the new CA while an open session goes on.
"""
import json
import os
import shutil
import signal
import socket
import ssl
import subprocess
import sys
import tempfile
import time

LUXRADD, LUXRAD, CORNELL = sys.argv[1], sys.argv[2], sys.argv[3]


class Failure(Exception):
    pass


def check(cond, what):
    if not cond:
        raise Failure(what)


def run(*cmd, ok=True, env=None):
    p = subprocess.run(cmd, capture_output=True, text=True, env=env,
                       timeout=300)
    if ok and p.returncode != 0:
        raise Failure("%s: exit %d\n%s%s" % (" ".join(cmd), p.returncode,
                                             p.stdout, p.stderr))
    return p


def make_ca(dirname, name):
    """A CA and a server certificate it signs, for 127.0.0.1/localhost."""
    ca_key, ca = os.path.join(dirname, name + "-ca.key"), \
        os.path.join(dirname, name + "-ca.pem")
    key, csr, cert = (os.path.join(dirname, name + s)
                      for s in ("-key.pem", ".csr", "-cert.pem"))
    ext = os.path.join(dirname, name + ".ext")
    with open(ext, "w") as f:
        f.write("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    run("openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
        "ec_paramgen_curve:P-256", "-nodes", "-keyout", ca_key, "-out", ca,
        "-days", "2", "-subj", "/CN=luxrad test CA " + name)
    run("openssl", "req", "-newkey", "ec", "-pkeyopt",
        "ec_paramgen_curve:P-256", "-nodes", "-keyout", key, "-out", csr,
        "-subj", "/CN=localhost")
    run("openssl", "x509", "-req", "-in", csr, "-CA", ca, "-CAkey", ca_key,
        "-CAcreateserial", "-out", cert, "-days", "2", "-extfile", ext)
    return ca, cert, key


class Daemon:
    def __init__(self, tmp, *args):
        self.dir = tempfile.mkdtemp(dir=tmp)
        self.log = open(os.path.join(self.dir, "log"), "w+")
        self.p = subprocess.Popen(
            [LUXRADD, "--data-dir", self.dir, "--listen-tcp", "127.0.0.1:0",
             "--listen-unix", "none", "--metrics-listen", "none",
             "--modbus-listen", "none", "--workers", "1",
             "--solver-threads", "1", "--log-level", "debug"] + list(args),
            stdout=self.log, stderr=subprocess.STDOUT)
        addr = os.path.join(self.dir, "luxradd.addr")
        end = time.monotonic() + 30
        while not os.path.exists(addr):
            check(self.p.poll() is None, "luxradd exited: " + self.text())
            check(time.monotonic() < end, "no luxradd.addr")
            time.sleep(0.02)
        line = [l for l in open(addr).read().splitlines()
                if l.startswith("tcp ")][0]
        check(line.endswith(" tls"), "addr line: %r" % line)
        self.port = int(line.split()[1].rsplit(":", 1)[1])

    def text(self):
        self.log.flush()
        self.log.seek(0)
        return self.log.read()[-3000:]

    def stop(self):
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
            self.p.wait(30)


def tls_socket(port, ca):
    ctx = ssl.create_default_context(cafile=ca)
    raw = socket.create_connection(("127.0.0.1", port), timeout=30)
    return ctx.wrap_socket(raw, server_hostname="127.0.0.1")


def frames(s, n):
    """Read n newline-terminated JSON frames (no payloads)."""
    buf, out = b"", []
    while len(out) < n:
        d = s.recv(65536)
        if not d:
            break
        buf += d
        while b"\n" in buf and len(out) < n:
            line, buf = buf.split(b"\n", 1)
            out.append(json.loads(line))
    return out


def call(s, req):
    s.sendall((json.dumps(req) + "\n").encode())
    return frames(s, 1)[0]


def main():
    tmp = tempfile.mkdtemp(prefix="luxrad-tls-")
    daemons = []
    try:
        ca, cert, key = make_ca(tmp, "a")
        ca2, cert2, key2 = make_ca(tmp, "b")
        users = os.path.join(tmp, "users")
        token = run(LUXRADD, "user-add", "alice", "submit", "--users-file",
                    users).stdout.strip()

        # Beyond loopback, no certificate: refused at start.
        p = subprocess.run([LUXRADD, "--data-dir", tempfile.mkdtemp(dir=tmp),
                            "--listen-tcp", "0.0.0.0:0", "--listen-unix",
                            "none", "--metrics-listen", "none",
                            "--modbus-listen", "none", "--users-file",
                            users], capture_output=True, text=True,
                           timeout=60)
        check(p.returncode == 2 and "tls_cert_file" in p.stderr,
              "listening beyond loopback without a certificate: exit %d, "
              "%s" % (p.returncode, p.stderr[-500:]))
        print("refused to start beyond loopback without a certificate")

        # Live copies of the files, so SIGHUP can renew them.
        live_cert, live_key = (os.path.join(tmp, n)
                               for n in ("live-cert.pem", "live-key.pem"))
        shutil.copy(cert, live_cert)
        shutil.copy(key, live_key)
        d = Daemon(tmp, "--tls", "all", "--tls-cert-file", live_cert,
                   "--tls-key-file", live_key, "--users-file", users,
                   "--max-connections", "3")
        daemons.append(d)

        s = tls_socket(d.port, ca)
        check(s.version() in ("TLSv1.2", "TLSv1.3"), s.version())
        r = call(s, {"cmd": "hello", "version": 1, "id": 1,
                     "token": token})
        check(r.get("ok") and r["user"] == {"name": "alice",
                                            "role": "submit"}, r)
        r = call(s, {"cmd": "status", "id": 2})
        check(r.get("ok"), r)
        print("python ssl: %s, %s, hello as alice, status ok"
              % (s.version(), s.cipher()[0]))

        try:
            tls_socket(d.port, ca2).close()
            raise Failure("a client trusting another CA connected")
        except ssl.SSLCertVerificationError as e:
            print("another CA: refused (%s)" % e.verify_message)

        p = run("openssl", "s_client", "-connect", "127.0.0.1:%d" % d.port,
                "-CAfile", ca, "-verify_return_error", "-brief", ok=False,
                env=dict(os.environ))
        out = p.stdout + p.stderr
        check("Verification: OK" in out or "Verify return code: 0" in out,
              "openssl s_client: " + out[-800:])
        print("openssl s_client: verification OK")

        plain = socket.create_connection(("127.0.0.1", d.port), timeout=30)
        plain.sendall(b'{"cmd": "hello", "version": 1}\n')
        r = frames(plain, 1)
        check(r and r[0]["error"]["code"] == "bad_frame" and
              "TLS" in r[0]["error"]["message"], "plain client: %r" % r)
        plain.close()
        print("plain client: told %r" % r[0]["error"]["message"])

        env = dict(os.environ, LUXRAD_TOKEN=token)
        addr = "tls://127.0.0.1:%d" % d.port
        p = run(LUXRAD, "--connect", addr, "--tls-ca", ca, "submit",
                CORNELL, "--solve", env=env)
        job = p.stdout.split()[-1]
        run(LUXRAD, "--connect", addr, "--tls-ca", ca, "watch", job,
            env=env)
        pts = os.path.join(tmp, "pts")
        with open(pts, "w") as f:
            f.write("0.278 0.001 0.28 0 1 0\n")
        p = run(LUXRAD, "--connect", addr, "--tls-ca", ca, "query", job,
                "--points", pts, env=env)
        lux = float(p.stdout.strip().splitlines()[-1].split(",")[-2])
        check(lux > 1, "lux %r" % p.stdout)
        p = run(LUXRAD, "--connect", addr, "status", ok=False, env=env)
        check(p.returncode == 3 and "TLS" in p.stderr,
              "without the CA: exit %d %s" % (p.returncode, p.stderr))
        print("luxrad over TLS: job %s solved, %.1f lux; without the CA: "
              "exit 3" % (job, lux))

        # Over the limit (3): the refusal inside TLS.
        held = [tls_socket(d.port, ca) for _ in range(2)]
        extra = tls_socket(d.port, ca)
        r = frames(extra, 1)
        check(r and r[0]["error"]["code"] == "too_many_connections",
              "over the limit: %r" % r)
        print("over the limit: %r inside TLS" % r[0]["error"]["message"])
        for h in held + [extra]:
            h.close()

        # A renewed certificate (another CA) on SIGHUP.
        shutil.copy(cert2, live_cert)
        shutil.copy(key2, live_key)
        d.p.send_signal(signal.SIGHUP)
        end = time.monotonic() + 20
        while True:
            try:
                n = tls_socket(d.port, ca2)
                break
            except (ssl.SSLError, OSError):
                check(time.monotonic() < end,
                      "the renewed certificate was not loaded: "
                      + d.text())
                time.sleep(0.1)
        check(call(n, {"cmd": "hello", "version": 1, "id": 1,
                       "token": token}).get("ok"), "hello after renewal")
        check(call(s, {"cmd": "status", "id": 3}).get("ok"),
              "the session opened before the renewal")
        n.close()
        s.close()
        print("SIGHUP: renewed certificate served, open session kept")
        print("test_daemon_tls: all checks passed")
        return 0
    except Failure as e:
        print("FAIL: %s" % e)
        for d in daemons:
            print("----- luxradd log -----\n" + d.text())
        return 1
    finally:
        for d in daemons:
            d.stop()
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
