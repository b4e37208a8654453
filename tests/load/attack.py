#!/usr/bin/env python3
"""attack.py: cheap attacks on a running clipmapd, written against docs/PROTOCOL.md (cmproto),
while a well-behaved client measures how long its HELLO -> HELLO_OK takes and
`clipmapctl status` must keep answering.

Scenarios (each while the probes run):
  idle    N connections that never send HELLO (256), reopened as the daemon closes them; on
          TCP they come from 32 loopback source addresses (a spread-out attacker)
  big     waves of 48 connections each announcing a 16 MiB frame before HELLO (a server-to-
          client TILE) and sending its body as fast as the daemon takes it
  slow    one connection that never says HELLO, one that leaves a frame half sent after
          HELLO: the daemon must close them (checked when --handshake-timeout /
          --frame-timeout say what to expect)
  inject  a HELLO name and an OPEN planet name holding a newline and an escape sequence
          (the daemon's log must escape them; the caller reads the log)

Probes: a client on the Unix socket (and on TCP from 127.0.0.2 when --tcp is given) connects,
says HELLO, waits for HELLO_OK, says BYE, every 50 ms; the daemon's RSS is read from
/proc/PID/status. Prints one line per figure and a final "summary: {json}"; exits 0 when
every goal holds (no probe failed, HELLO p99 <= --p99-ms, status answered, RSS growth <=
--rss-mb, every 16 MiB frame refused without being buffered, slow connections closed in
time), 1 otherwise, 2 on bad usage.

  --short   a few seconds per scenario (make check)
  --long    idle and big for 90 s each (the campaign's figures)
"""
import argparse
import json
import os
import selectors
import socket
import subprocess
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cmproto  # noqa: E402

BIG = 16 << 20


def rss_kib(pid):
    try:
        with open("/proc/%d/status" % pid) as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def pct(xs, p):
    if not xs:
        return None
    ys = sorted(xs)
    i = min(len(ys) - 1, max(0, int(round(p / 100.0 * len(ys) + 0.5)) - 1))
    return ys[i]


class Probes:
    """Background measurements: HELLO latency per address, clipmapctl status, RSS."""

    def __init__(self, args):
        self.args = args
        self.stop = threading.Event()
        self.lock = threading.Lock()
        self.lat = {}    # label -> [seconds]
        self.fail = {}   # label -> [reasons]
        self.ctl_ok = self.ctl_fail = 0
        self.ctl_errors = []
        self.rss = []
        self.threads = []

    def _hello_loop(self, label, addr, source):
        token = self.args.token
        while not self.stop.is_set():
            try:
                s, _, _, dt = cmproto.handshake(addr, token=token, name="attack-probe/1",
                                                timeout=5.0, source=source)
                try:
                    s.sendall(cmproto.bye())
                except OSError:
                    pass
                s.close()
                with self.lock:
                    self.lat.setdefault(label, []).append(dt)
            except (OSError, RuntimeError) as e:
                with self.lock:
                    self.fail.setdefault(label, []).append(str(e))
            self.stop.wait(0.05)

    def _ctl_loop(self):
        while not self.stop.is_set():
            try:
                r = subprocess.run([self.args.ctl, "-s", self.args.unix, "status"],
                                   stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                   timeout=10)
                ok = r.returncode == 0
                why = "exit %d: %s" % (r.returncode, r.stdout.decode(errors="replace")[-200:])
            except (OSError, subprocess.TimeoutExpired) as e:
                ok, why = False, str(e)
            with self.lock:
                if ok:
                    self.ctl_ok += 1
                else:
                    self.ctl_fail += 1
                    self.ctl_errors.append(why)
            self.stop.wait(1.0)

    def _rss_loop(self):
        while not self.stop.is_set():
            v = rss_kib(self.args.pid)
            if v is not None:
                with self.lock:
                    self.rss.append(v)
            self.stop.wait(0.2)

    def start(self):
        targets = [("unix", self.args.unix, None)]
        if self.args.tcp:
            targets.append(("tcp", self.args.tcp, "127.0.0.2"))
        for label, addr, src in targets:
            self.threads.append(threading.Thread(target=self._hello_loop,
                                                 args=(label, addr, src), daemon=True))
        if self.args.ctl:
            self.threads.append(threading.Thread(target=self._ctl_loop, daemon=True))
        if self.args.pid:
            self.threads.append(threading.Thread(target=self._rss_loop, daemon=True))
        for t in self.threads:
            t.start()

    def finish(self):
        self.stop.set()
        for t in self.threads:
            t.join(15)

    def take(self):
        """The figures since the last take (and resets them)."""
        with self.lock:
            out = {"lat": self.lat, "fail": self.fail, "ctl_ok": self.ctl_ok,
                   "ctl_fail": self.ctl_fail, "ctl_errors": self.ctl_errors[:3],
                   "rss": self.rss}
            self.lat, self.fail, self.rss, self.ctl_errors = {}, {}, [], []
            self.ctl_ok = self.ctl_fail = 0
        return out


def attack_addr(args):
    return args.tcp if args.tcp else args.unix


def scenario_idle(args, n, seconds):
    """n pre-auth connections held (reopened when the daemon closes one). Returns figures."""
    sel = selectors.DefaultSelector()
    socks = {}
    opened = closed = refused = 0
    target = attack_addr(args)

    def open_one(i):
        nonlocal opened, refused
        src = "127.0.0.%d" % (10 + i % 32) if args.tcp else None
        try:
            s = cmproto.connect(target, timeout=2.0, source=src)
        except OSError:
            refused += 1
            return
        s.setblocking(False)
        socks[i] = s
        sel.register(s, selectors.EVENT_READ, i)
        opened += 1

    end = time.monotonic() + seconds
    next_fill = 0.0
    while time.monotonic() < end:
        now = time.monotonic()
        if now >= next_fill:
            for i in range(n):
                if i not in socks:
                    open_one(i)
            next_fill = now + 0.5
        for key, _ in sel.select(timeout=0.1):
            s, i = key.fileobj, key.data
            try:
                data = s.recv(65536)
            except OSError:
                data = b""
            if not data:
                sel.unregister(s)
                s.close()
                del socks[i]
                closed += 1
    held = len(socks)
    for s in socks.values():
        s.close()
    sel.close()
    return {"connections": n, "opened": opened, "closed_by_daemon": closed,
            "connect_failed": refused, "held_at_end": held}


def big_wave(target, n, limit):
    """n connections announce a 16 MiB TILE before HELLO and push its body until the daemon
    closes them (or limit s). Returns their states."""
    sel = selectors.DefaultSelector()
    state = {}
    chunk = b"\0" * 65536
    for _ in range(n):
        try:
            s = cmproto.connect(target, timeout=2.0)
        except OSError:
            continue
        s.setblocking(False)
        state[s] = {"sent": 0, "hdr": cmproto.header(cmproto.TILE, BIG), "done": False,
                    "t0": time.monotonic(), "closed_s": None, "rd": cmproto.Reader(),
                    "error": None}
        sel.register(s, selectors.EVENT_READ | selectors.EVENT_WRITE)
    end = time.monotonic() + limit
    while time.monotonic() < end and any(not st["done"] for st in state.values()):
        for key, ev in sel.select(timeout=0.1):
            s = key.fileobj
            st = state[s]
            gone = False
            if ev & selectors.EVENT_READ:
                try:
                    data = s.recv(65536)
                    if data:
                        st["rd"].feed(data)
                        f = st["rd"].next()
                        if f and f[0] == cmproto.ERROR:
                            st["error"] = cmproto.decode_error(f[1])["name"]
                    else:
                        gone = True
                except OSError:
                    gone = True
            if not gone and ev & selectors.EVENT_WRITE:
                try:
                    if st["hdr"]:
                        k = s.send(st["hdr"])
                        st["hdr"] = st["hdr"][k:]
                    elif st["sent"] < BIG:
                        k = s.send(chunk[:min(len(chunk), BIG - st["sent"])])
                        st["sent"] += k
                    else:
                        sel.modify(s, selectors.EVENT_READ)
                except BlockingIOError:
                    pass
                except OSError:
                    gone = True
            if gone:
                st["done"] = True
                st["closed_s"] = time.monotonic() - st["t0"]
                sel.unregister(s)
    for s in state:
        s.close()
    sel.close()
    return list(state.values())


def scenario_big(args, n, seconds):
    """Waves of n 16 MiB pre-auth frames for `seconds`. Returns figures."""
    target = attack_addr(args)
    end = time.monotonic() + seconds
    waves = opened = closed = total = 0
    body_max = 0
    close_max = 0.0
    errors = {}
    while True:
        sts = big_wave(target, n, 10.0)
        waves += 1
        opened += len(sts)
        closed += sum(1 for st in sts if st["done"])
        total += sum(st["sent"] for st in sts)
        body_max = max([body_max] + [st["sent"] for st in sts])
        close_max = max([close_max] + [st["closed_s"] or 0 for st in sts])
        for st in sts:
            if st["error"]:
                errors[st["error"]] = errors.get(st["error"], 0) + 1
        if time.monotonic() >= end:
            break
        time.sleep(0.05)
    return {"connections": n, "waves": waves, "opened": opened, "closed_by_daemon": closed,
            "body_bytes_max": body_max, "body_bytes_total": total,
            "close_s_max": round(close_max, 3), "errors_read": errors}


def wait_closed(s, limit):
    """Seconds until the daemon closes s (its ERROR read on the way), or None after limit;
    the ERROR's code name too."""
    t0 = time.monotonic()
    rd = cmproto.Reader()
    err = None
    try:
        while True:
            f = cmproto.recv_frame(s, rd, t0 + limit)
            if f is None:
                return time.monotonic() - t0, err
            if f[0] == cmproto.ERROR:
                err = cmproto.decode_error(f[1])["name"]
    except socket.timeout:
        return None, err
    except OSError:
        return time.monotonic() - t0, err


def scenario_slow(args):
    out = {}
    if args.handshake_timeout:
        s = cmproto.connect(args.unix)
        t, err = wait_closed(s, args.handshake_timeout + args.slack + 3)
        s.close()
        out["silent_closed_s"], out["silent_error"] = t, err
    if args.frame_timeout:
        s, _, _, _ = cmproto.handshake(args.unix, token=args.token, name="attack-slow/1")
        s.sendall(cmproto.stats_req(7)[:7])  # half a header, and nothing more
        t, err = wait_closed(s, args.frame_timeout + args.slack + 3)
        s.close()
        out["partial_closed_s"], out["partial_error"] = t, err
    return out


def scenario_inject(args):
    """A HELLO name and an OPEN name with control characters; returns the ERROR's code."""
    name = "ok\nerror: FORGED-HELLO\x1b[31m"
    s, rd, _, _ = cmproto.handshake(args.unix, token=args.token, name=name)
    s.sendall(cmproto.open_planet("evil\nerror: FORGED-OPEN\x1b]0;x\x07", req=9))
    f = cmproto.recv_frame(s, rd, time.monotonic() + 5)
    s.sendall(cmproto.bye())
    s.close()
    return {"open_answer": cmproto.decode_error(f[1])["name"] if f and f[0] == cmproto.ERROR
            else (f[0] if f else None)}


def lat_figures(lat):
    out = {}
    for label, xs in lat.items():
        out[label] = {"n": len(xs), "p50_ms": round(pct(xs, 50) * 1e3, 2),
                      "p99_ms": round(pct(xs, 99) * 1e3, 2),
                      "max_ms": round(max(xs) * 1e3, 2)}
    return out


def run_phase(name, probes, fn, rss0, args, goals):
    figs = fn()
    p = probes.take()
    figs["hello"] = lat_figures(p["lat"])
    figs["probe_failures"] = {k: len(v) for k, v in p["fail"].items()}
    figs["probe_failure_examples"] = {k: v[:3] for k, v in p["fail"].items()}
    figs["status_ok"], figs["status_failed"] = p["ctl_ok"], p["ctl_fail"]
    if p["ctl_errors"]:
        figs["status_errors"] = p["ctl_errors"]
    if p["rss"] and rss0:
        figs["rss_mib_max"] = round(max(p["rss"]) / 1024.0, 1)
        figs["rss_growth_mib"] = round((max(p["rss"]) - rss0) / 1024.0, 1)
    for label, f in figs["hello"].items():
        print("%s: hello %s: n %d p50 %.2f ms p99 %.2f ms max %.2f ms" %
              (name, label, f["n"], f["p50_ms"], f["p99_ms"], f["max_ms"]))
        if f["p99_ms"] > args.p99_ms:
            goals.append("%s: %s HELLO p99 %.1f ms > %g ms" % (name, label, f["p99_ms"],
                                                               args.p99_ms))
    for label, k in figs["probe_failures"].items():
        if k:
            goals.append("%s: %d %s probes failed (%s)" %
                         (name, k, label, figs["probe_failure_examples"][label][0]))
    if args.ctl and (figs["status_failed"] or not figs["status_ok"]):
        goals.append("%s: clipmapctl status failed %d times, answered %d" %
                     (name, figs["status_failed"], figs["status_ok"]))
    if figs.get("rss_growth_mib", 0) > args.rss_mb:
        goals.append("%s: RSS grew %.1f MiB > %g" % (name, figs["rss_growth_mib"], args.rss_mb))
    print("%s: %s" % (name, json.dumps({k: v for k, v in figs.items() if k != "hello"})))
    return figs


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--unix", required=True, help="the daemon's Unix socket")
    ap.add_argument("--tcp", help="HOST:PORT of a TCP listener: the attacks go there")
    ap.add_argument("--token-file", help="token for the probes (TCP listeners that need it)")
    ap.add_argument("--pid", type=int, help="the daemon's pid, for its RSS")
    ap.add_argument("--ctl", help="clipmapctl, run as `status` every second")
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--short", action="store_true", help="seconds per scenario (make check)")
    g.add_argument("--long", action="store_true", help="90 s per scenario")
    ap.add_argument("--seconds", type=float, help="override the duration per scenario")
    ap.add_argument("--idle", type=int, default=256, help="idle pre-auth connections")
    ap.add_argument("--big", type=int, default=48, help="connections announcing 16 MiB")
    ap.add_argument("--p99-ms", type=float, default=100.0, help="goal for HELLO p99")
    ap.add_argument("--rss-mb", type=float, default=64.0, help="goal for RSS growth")
    ap.add_argument("--handshake-timeout", type=float, help="the daemon's, to check")
    ap.add_argument("--frame-timeout", type=float, help="the daemon's, to check")
    ap.add_argument("--slack", type=float, default=2.0,
                    help="seconds a timeout's close may come late (sanitizer builds: more)")
    ap.add_argument("--scenarios", default="idle,big,slow,inject")
    args = ap.parse_args()
    if args.tcp:
        host, _, port = args.tcp.rpartition(":")
        if not host or not port.isdigit():
            ap.error("--tcp: expected HOST:PORT")
        args.tcp = (host, int(port))
    args.token = b""
    if args.token_file:
        with open(args.token_file, "rb") as f:
            args.token = f.read().rstrip(b"\r\n")
    seconds = args.seconds or (90.0 if args.long else 3.0)
    which = set(args.scenarios.split(","))
    unknown = which - {"idle", "big", "slow", "inject"}
    if unknown:
        ap.error("unknown scenario %s" % ",".join(sorted(unknown)))

    rss0 = rss_kib(args.pid) if args.pid else None
    probes = Probes(args)
    probes.start()
    goals, summary = [], {"rss_mib_start": round(rss0 / 1024.0, 1) if rss0 else None}
    time.sleep(min(2.0, seconds / 2))
    summary["baseline"] = run_phase("baseline", probes, lambda: {}, rss0, args, goals)
    if "idle" in which:
        summary["idle"] = run_phase("idle", probes,
                                    lambda: scenario_idle(args, args.idle, seconds), rss0,
                                    args, goals)
    if "big" in which:
        f = run_phase("big", probes, lambda: scenario_big(args, args.big, seconds), rss0,
                      args, goals)
        summary["big"] = f
        if f["opened"] != args.big * f["waves"] or f["closed_by_daemon"] != f["opened"]:
            goals.append("big: %d of %d connections closed by the daemon" %
                         (f["closed_by_daemon"], f["opened"]))
        if f["body_bytes_max"] >= BIG:
            goals.append("big: a 16 MiB body was taken whole")
    probes.finish()
    if "slow" in which:
        f = scenario_slow(args)
        summary["slow"] = f
        print("slow: %s" % json.dumps(f))
        if args.handshake_timeout:
            t = f["silent_closed_s"]
            if t is None or t > args.handshake_timeout + args.slack or \
                    t < args.handshake_timeout - 0.3:
                goals.append("slow: a silent connection closed after %s s (handshake_timeout %g)"
                             % (t, args.handshake_timeout))
        if args.frame_timeout:
            t = f["partial_closed_s"]
            if t is None or t > args.frame_timeout + args.slack:
                goals.append("slow: a half-sent frame closed after %s s (frame_timeout %g)" %
                             (t, args.frame_timeout))
    if "inject" in which:
        f = scenario_inject(args)
        summary["inject"] = f
        print("inject: %s" % json.dumps(f))
        if f["open_answer"] != "not-found":
            goals.append("inject: OPEN of an unknown name answered %s" % f["open_answer"])
    rss1 = rss_kib(args.pid) if args.pid else None
    summary["rss_mib_end"] = round(rss1 / 1024.0, 1) if rss1 else None
    summary["failed"] = goals
    print("summary: " + json.dumps(summary, sort_keys=True))
    for g in goals:
        print("FAILED: " + g)
    print("attack: %s" % ("every goal held" if not goals else "%d goals missed" % len(goals)))
    return 1 if goals else 0


if __name__ == "__main__":
    sys.exit(main())
