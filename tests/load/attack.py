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
  corridor the campaign's 67-byte PREFETCH (a corridor 9.55e6 m wide at level 22) and a
          whole-planet bbox at level 11 from a client without the token: ERROR limit at once
  moving  --sessions (200) sessions fly back and forth over --region-deg of the equator, each
          asking for the 4x4 windows of --levels in up to 3 layers (288 tiles with 2-7) and a
          new WANT whenever its windows move; one session first asks for every tile of the
          routes, so all are in the cache; measured: each tile's WANT -> TILE latency (goal
          p99 <= --tile-p99-ms, 5 s), the daemon's event-loop iterations over 50 ms from its
          STATS, by why (goal: none of its own work or waits; those it spent preempted by
          other processes are reported), tiles generated meanwhile; then all close at once
          (no BYE) and a new client's HELLO is timed

Probes: a client on the Unix socket (and on TCP from 127.0.0.2 when --tcp is given) connects,
says HELLO, waits for HELLO_OK, says BYE, every 50 ms; closed before HELLO_OK (evicted as the
oldest pre-auth connection: its HELLO had not arrived), it reconnects once after 0.1 s as
clipmapview does, and the latency counts both. The daemon's RSS is read from
/proc/PID/status. Prints one line per figure and a final "summary: {json}"; exits 0 when
every goal holds (every probe completed, its retry included, at most 1 in 20 evicted, HELLO
p99 <= --p99-ms, status answered, RSS growth <= --rss-mb, every 16 MiB frame refused
without being buffered, slow connections closed in time), 1 otherwise, 2 on bad usage.

  --short   a few seconds per scenario (make check runs idle,big,slow,inject,corridor so;
            moving in a short form of its own: tests/integration/test_attack.c)
  --long    90 s per scenario (the campaign's figures; moving with 200 sessions)
"""
import argparse
import json
import math
import multiprocessing
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
        self.evicted = {}  # label -> [reasons]: closed before HELLO_OK, the retry answered
        self.ctl_ok = self.ctl_fail = 0
        self.ctl_errors = []
        self.rss = []
        self.threads = []

    def _hello_loop(self, label, addr, source):
        token = self.args.token
        while not self.stop.is_set():
            t0 = time.monotonic()
            first = None
            for attempt in range(2):
                try:
                    s, _, _, _ = cmproto.handshake(addr, token=token, name="attack-probe/1",
                                                   timeout=5.0, source=source)
                    try:
                        s.sendall(cmproto.bye())
                    except OSError:
                        pass
                    s.close()
                    with self.lock:
                        self.lat.setdefault(label, []).append(time.monotonic() - t0)
                        if first:
                            self.evicted.setdefault(label, []).append(first)
                    break
                except (OSError, RuntimeError) as e:
                    # Closed without a word before HELLO_OK: the daemon evicted this
                    # connection as the oldest pre-auth one (its HELLO not yet arrived: the
                    # probe was descheduled between connect and send while the flood's
                    # connections queued behind it). clipmapview reconnects after 0.1 s;
                    # so does the probe, once, and the latency counts the retry.
                    evicted = str(e) == "closed before HELLO_OK" or \
                        isinstance(e, (ConnectionResetError, BrokenPipeError))
                    if attempt == 0 and evicted and not self.stop.is_set():
                        first = str(e)
                        self.stop.wait(0.1)
                        continue
                    with self.lock:
                        self.fail.setdefault(label, []).append(
                            str(e) if not first else "%s, then %s" % (first, e))
                    break
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
            out = {"lat": self.lat, "fail": self.fail, "evicted": self.evicted,
                   "ctl_ok": self.ctl_ok,
                   "ctl_fail": self.ctl_fail, "ctl_errors": self.ctl_errors[:3],
                   "rss": self.rss}
            self.lat, self.fail, self.rss, self.ctl_errors = {}, {}, [], []
            self.evicted = {}
            self.ctl_ok = self.ctl_fail = 0
        return out


def _probe_main(args, conn):
    probes = Probes(args)
    probes.start()
    while True:
        cmd = conn.recv()
        if cmd == "take":
            conn.send(probes.take())
        else:
            probes.finish()
            conn.send(None)
            return


class ProbeProcess:
    """The probes in a process of their own: the attacks' Python loops (256 sockets reopened,
    16 MiB bodies pushed) then cannot hold them back on the GIL between connect and HELLO,
    where a slow probe looks like an idle attacker and is rightly evicted, nor add their
    waits to the HELLO latency measured."""

    def __init__(self, args):
        ctx = multiprocessing.get_context("fork")
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_probe_main, args=(args, child), daemon=True)
        self.proc.start()
        child.close()

    def take(self):
        self.conn.send("take")
        return self.conn.recv()

    def finish(self):
        self.conn.send("finish")
        self.conn.recv()
        self.proc.join(20)


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


def stats_now(args):
    """The daemon's STATS as a dict, over a session of its own."""
    s, rd, _, _ = cmproto.handshake(args.unix, token=args.token, name="attack-stats/1")
    try:
        s.sendall(cmproto.stats_req(5))
        while True:
            f = cmproto.recv_frame(s, rd, time.monotonic() + 10)
            if f is None:
                raise RuntimeError("closed before STATS")
            if f[0] == cmproto.STATS:
                return cmproto.decode_stats(f[1])[1]
    finally:
        s.close()


def open_session(addr, token, planet_name, name):
    """A session with the planet open: (socket, planet id, planet record, HELLO_OK)."""
    s, rd, ok, _ = cmproto.handshake(addr, token=token, name=name, timeout=10.0)
    s.sendall(cmproto.open_planet(planet_name, req=1))
    f = cmproto.recv_frame(s, rd, time.monotonic() + 10)
    if f is None or f[0] != cmproto.OPENED:
        s.close()
        raise RuntimeError("OPEN %s: %s" % (planet_name, cmproto.decode_error(f[1])["message"]
                                            if f and f[0] == cmproto.ERROR else "no OPENED"))
    pid, pl = cmproto.decode_opened(f[1])
    return s, pid, pl, ok


def first_planet(args):
    s, rd, _, _ = cmproto.handshake(args.unix, token=args.token, name="attack-list/1")
    try:
        s.sendall(cmproto.list_planets(3))
        f = cmproto.recv_frame(s, rd, time.monotonic() + 10)
        if f is None or f[0] != cmproto.PLANETS:
            raise RuntimeError("no PLANETS")
        planets = cmproto.decode_planets(f[1])
        if not planets:
            raise RuntimeError("the daemon serves no planet")
        return planets[0]["name"]
    finally:
        s.close()


class Route:
    """Where moving session i is at time t, and the want-set a viewer there asks for: per
    level ly of `levels` (coarse first), per layer, the 4x4 tiles centred on the focus on the
    isotropic lx = ly + 1 of the equator. Sessions go back and forth (never jump) over
    `region` degrees of longitude at `speed` deg/s, spread evenly along it, so the tiles of
    the whole scenario are a known, bounded set the warm-up puts in the cache."""

    def __init__(self, args, planet, n):
        self.levels = args.levels
        self.nlayers = min(3, len(planet["layers"]))
        self.region, self.speed, self.n = args.region_deg, args.speed_dps, n
        self.lon0 = -args.region_deg / 2.0
        self.radius = planet["a"]

    def focus(self, i, t):
        """(lon, east velocity in m/s) of session i at time t."""
        period = 2.0 * self.region / self.speed
        u = ((i / float(self.n)) * period + t) % period
        d = u * self.speed
        east = d <= self.region
        lon = self.lon0 + (d if east else 2 * self.region - d)
        v = self.speed * math.pi / 180.0 * self.radius
        return lon, (v if east else -v)

    def sig(self, lon):
        """What the want-set at lon depends on: each level's first column."""
        return tuple(int(math.floor((lon + 180.0) / 360.0 * (2 << ly) + 0.5)) for ly in self.levels)

    def window(self, lon):
        """The want-set entries (layer, class, lx, ly, x, y) at longitude lon (equator)."""
        out = []
        for ly in self.levels:
            lx = ly + 1
            nx, ny = 1 << lx, 1 << ly
            fx = (lon + 180.0) / 360.0 * nx
            x0 = int(math.floor(fx + 0.5)) - 2
            y0 = min(max(ny // 2 - 2, 0), max(ny - 4, 0))
            for layer in range(self.nlayers):
                for dy in range(min(4, ny)):
                    for dx in range(min(4, nx)):
                        out.append((layer, cmproto.CLASS_VISIBLE, lx, ly, (x0 + dx) % nx,
                                    y0 + dy))
        return out

    def union(self):
        """Every entry any session asks for, and the server's look-ahead's margin (4 s at
        the speed) on both ends."""
        seen, out = set(), []
        margin = 4.5 * self.speed + 1.0
        lo, hi = self.lon0 - margin, self.lon0 + self.region + margin
        step = 360.0 / (1 << (max(self.levels) + 1)) / 2.0
        lon = lo
        while lon <= hi + step:
            for e in self.window(lon):
                if e not in seen:
                    seen.add(e)
                    out.append(e)
            lon += step
        return out


def warm(args, route, planet_name, tile_bytes):
    """One session wants the route's whole set and waits for every tile: the cache then
    holds what the moving sessions will ask for. Returns figures."""
    entries = route.union()
    t0 = time.monotonic()
    s, pid, pl, ok = open_session(args.unix, args.token, planet_name, "attack-warm/1")
    sk = cmproto.Skimmer()
    got, failed, seq = 0, 0, 0
    chunk = max(1, min(ok["max_want"] or 4096, 4096))
    try:
        for k in range(0, len(entries), chunk):
            part = entries[k:k + chunk]
            seq += 1
            s.sendall(cmproto.want(pid, seq, part, lon=0.0, lat=0.0, alt=1e6))
            left = {e[:1] + e[2:] for e in part}
            deadline = time.monotonic() + args.warm_timeout
            s.settimeout(1.0)
            while left and time.monotonic() < deadline:
                try:
                    frames = sk.pump(s)
                except socket.timeout:
                    continue
                if frames is None:
                    raise RuntimeError("the daemon closed the warm-up session")
                for mtype, head, _ in frames:
                    if mtype == cmproto.TILE:
                        left.discard(cmproto.tile_key(head)[1])
                        got += 1
                    elif mtype == cmproto.TILE_FAIL:
                        left.discard(cmproto.tile_fail_key(head)[1])
                        failed += 1
                    elif mtype == cmproto.ERROR:
                        raise RuntimeError("warm-up: ERROR %s" % cmproto.decode_error(head)["message"])
            if left:
                raise RuntimeError("warm-up: %d tiles not sent within %g s" %
                                   (len(left), args.warm_timeout))
    finally:
        s.close()
    return {"wanted": len(entries), "received": got, "failed": failed,
            "mib": round(len(entries) * tile_bytes / 1048576.0, 1),
            "seconds": round(time.monotonic() - t0, 2)}


def moving_worker(args, planet_name, route, n, seconds, conn):
    """Runs in its own process (the probes' latency is not this loop's GIL): n sessions fly
    their routes for `seconds`, each sending a WANT when its set changes (at most every
    0.1 s); then all close at once. Sends back the figures."""
    try:
        conn.send(moving_run(args, planet_name, route, n, seconds))
    except Exception as e:  # noqa: BLE001 -- reported by the parent as a failed goal
        conn.send({"error": "%s: %s" % (type(e).__name__, e)})
    conn.close()


def moving_run(args, planet_name, route, n, seconds):
    sel = selectors.DefaultSelector()
    scratch = bytearray(1 << 20)
    sess = []
    t_conn = time.monotonic()
    for i in range(n):
        s, pid, _, _ = open_session(args.unix, args.token, planet_name, "attack-moving/1")
        s.setblocking(False)
        st = {"s": s, "pid": pid, "sk": cmproto.Skimmer(scratch), "seq": 0, "cur": set(),
              "pending": {}, "last": None, "t_want": 0.0}
        sess.append(st)
        sel.register(s, selectors.EVENT_READ, st)
    connect_s = time.monotonic() - t_conn
    lat, extra, fails, errors, wants, withdrawn, asked = [], 0, 0, [], 0, 0, 0
    t0 = time.monotonic()
    end = t0 + seconds
    while True:
        now = time.monotonic()
        if now >= end:
            break
        for i, st in enumerate(sess):
            if now - st["t_want"] < 0.1:
                continue
            lon, v = route.focus(i, now - t0)
            sig = route.sig(lon)
            if sig == st["last"]:
                continue
            entries = route.window(lon)
            new = {e[:1] + e[2:] for e in entries}
            for k in new - st["cur"]:
                st["pending"][k] = now
                asked += 1
            for k in st["cur"] - new:
                if st["pending"].pop(k, None) is not None:
                    withdrawn += 1  # left the set before it came: not in the latencies
            st["cur"], st["last"] = new, sig
            st["seq"] += 1
            st["t_want"] = now
            st["s"].setblocking(True)
            st["s"].sendall(cmproto.want(st["pid"], st["seq"], entries, lon=lon, lat=0.0,
                                         alt=1e5, vel=(v, 0.0, 0.0)))
            st["s"].setblocking(False)
            wants += 1
        for key, _ in sel.select(timeout=0.02):
            st = key.data
            try:
                frames = st["sk"].pump(st["s"])
            except (BlockingIOError, InterruptedError):
                continue
            if frames is None:
                raise RuntimeError("the daemon closed a moving session")
            t = time.monotonic()
            for mtype, head, _ in frames:
                if mtype == cmproto.TILE:
                    t_in = st["pending"].pop(cmproto.tile_key(head)[1], None)
                    if t_in is None:
                        extra += 1
                    else:
                        lat.append(t - t_in)
                elif mtype == cmproto.TILE_FAIL:
                    fails += 1
                elif mtype == cmproto.ERROR:
                    errors.append(cmproto.decode_error(head)["message"])
    dt = time.monotonic() - t0
    waiting = [time.monotonic() - t for st in sess for t in st["pending"].values()]
    # all at once, without BYE (clients that vanish)
    t_close = time.monotonic()
    for st in sess:
        st["s"].close()
    close_s = time.monotonic() - t_close
    sel.close()
    _, _, _, hello_s = cmproto.handshake(args.unix, token=args.token, name="attack-after/1",
                                         timeout=30.0)
    return {"sessions": n, "seconds": round(dt, 2), "connect_s": round(connect_s, 2),
            "wants": wants, "tiles_got": len(lat), "tiles_per_s": round(len(lat) / dt, 1),
            "tile_p50_ms": round(pct(lat, 50) * 1e3, 1) if lat else None,
            "tile_p99_ms": round(pct(lat, 99) * 1e3, 1) if lat else None,
            "tile_max_ms": round(max(lat) * 1e3, 1) if lat else None,
            "asked": asked, "withdrawn": withdrawn,
            "waiting_at_end": len(waiting),
            "waiting_oldest_ms": round(max(waiting) * 1e3, 1) if waiting else 0,
            "extra_tiles": extra, "tile_fails": fails, "errors": errors[:3],
            "close_all_s": round(close_s, 3),
            "hello_after_close_ms": round(hello_s * 1e3, 1)}


def scenario_moving(args, n, seconds):
    """Warm the route's tiles, then n sessions move for `seconds` asking for them and close
    at once. Returns figures; the daemon's loop and generation figures are deltas of its
    STATS over the moving part."""
    planet_name = args.planet or first_planet(args)
    s, _, pl, ok = open_session(args.unix, args.token, planet_name, "attack-plan/1")
    s.close()
    max_pending = ok["max_pending"]
    route = Route(args, pl, n)
    tile_bytes = pl["tile_size"] ** 2 * 4
    figs = {"planet": planet_name, "levels": "%d-%d" % (min(args.levels), max(args.levels)),
            "layers": route.nlayers, "region_deg": args.region_deg, "speed_dps": args.speed_dps,
            "want_set": len(route.window(0.0))}
    st_w = stats_now(args)
    figs["warm"] = warm(args, route, planet_name, tile_bytes)
    st0 = stats_now(args)
    # what the formula lets RSS grow by: the cache filling, and each session's held tiles and
    # queued output (2 x max_pending), on top of --rss-mb
    figs["rss_allow_mib"] = round((st_w.get("cache.budget", 0) - st_w.get("cache.bytes", 0) +
                                   2 * n * max_pending) / 1048576.0 + args.rss_mb, 1)
    if figs["warm"]["mib"] > st0.get("cache.budget", 0) / 1048576.0:
        figs["warning"] = "the route's tiles (%.0f MiB) exceed the cache (%.0f MiB)" % (
            figs["warm"]["mib"], st0.get("cache.budget", 0) / 1048576.0)
    ctx = multiprocessing.get_context("fork")
    rd, wr = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=moving_worker, args=(args, planet_name, route, n, seconds, wr))
    proc.start()
    wr.close()
    res = rd.recv() if rd.poll(seconds + n * 0.5 + 120) else {"error": "no answer from the worker"}
    proc.join(10)
    st1 = stats_now(args)
    figs.update(res)
    for k in ("sched.generated", "loop.over_50ms", "loop.over_50ms.work",
              "loop.over_50ms.blocked", "loop.over_50ms.preempted", "loop.iterations"):
        figs[k] = st1.get(k, 0) - st0.get(k, 0)
    figs["loop.max_ms_since_start"] = round(st1.get("loop.max_ms", 0), 1)
    figs["sessions_after"] = st1.get("sessions")
    return figs


def scenario_corridor(args):
    """The campaign's 67-byte PREFETCH (a corridor 9.55e6 m wide at level 22) and a bbox of
    the whole planet at level 11 from a client without the token: each refused at once."""
    planet_name = args.planet or first_planet(args)
    out = {}
    for label, msg in (("corridor", cmproto.prefetch_path(1, planet_name, 22, 22, 9.55e6,
                                                          [(0.0, 0.0)])),
                       ("planet_l11", cmproto.prefetch_bbox(2, planet_name, 0, 11, -180.0,
                                                            -90.0, 180.0, 90.0))):
        s, rd, _, _ = cmproto.handshake(args.unix, name="attack-prefetch/1")
        t0 = time.monotonic()
        s.sendall(msg)
        answer = None
        while True:
            f = cmproto.recv_frame(s, rd, t0 + 30)
            if f is None:
                answer = "closed"
                break
            if f[0] == cmproto.ERROR:
                answer = cmproto.decode_error(f[1])["name"]
                break
            if f[0] == cmproto.PREFETCH_PROGRESS:
                answer = "accepted"
                break
        out[label] = {"answer": answer, "ms": round((time.monotonic() - t0) * 1e3, 1),
                      "bytes": len(msg)}
        s.close()
    return out


def lat_figures(lat):
    out = {}
    for label, xs in lat.items():
        out[label] = {"n": len(xs), "p50_ms": round(pct(xs, 50) * 1e3, 2),
                      "p99_ms": round(pct(xs, 99) * 1e3, 2),
                      "max_ms": round(max(xs) * 1e3, 2)}
    return out


def run_phase(name, probes, fn, rss0, args, goals):
    t0 = time.monotonic()
    figs = fn()
    long_enough = time.monotonic() - t0 >= 2.5  # clipmapctl status runs every second
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
    # a probe that died or hung shows as no figures at all
    for label in ["unix"] + (["tcp"] if args.tcp else []):
        if long_enough and label not in figs["hello"] and not figs["probe_failures"].get(label):
            goals.append("%s: no %s probe completed" % (name, label))
    # A lockout shows as most probes evicted; one now and then is the race above.
    figs["probe_evicted"] = {k: len(v) for k, v in p["evicted"].items()}
    for label, k in figs["probe_evicted"].items():
        n = figs["hello"].get(label, {}).get("n", 0)
        if k > max(1, n // 20):
            goals.append("%s: %d of %d %s probes evicted before HELLO_OK (retried)" %
                         (name, k, n, label))
    if args.ctl and (figs["status_failed"] or (long_enough and not figs["status_ok"])):
        goals.append("%s: clipmapctl status failed %d times, answered %d" %
                     (name, figs["status_failed"], figs["status_ok"]))
    allow = figs.pop("rss_allow_mib", args.rss_mb)
    if figs.get("rss_growth_mib", 0) > allow:
        goals.append("%s: RSS grew %.1f MiB > %g" % (name, figs["rss_growth_mib"], allow))
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
    ap.add_argument("--scenarios", default="idle,big,slow,inject,corridor,moving",
                    help="any of idle,big,slow,inject,corridor,moving")
    ap.add_argument("--planet", help="planet for moving and corridor (default: the first)")
    ap.add_argument("--sessions", type=int, default=200, help="moving sessions")
    ap.add_argument("--levels", default="2-7", help="moving: the levels ly wanted, A-B")
    ap.add_argument("--region-deg", type=float, default=24.0,
                    help="moving: the longitudes the sessions fly back and forth over")
    ap.add_argument("--speed-dps", type=float, default=0.5, help="moving: degrees per second")
    ap.add_argument("--warm-timeout", type=float, default=300.0,
                    help="moving: seconds the warm-up may take")
    ap.add_argument("--tile-p99-ms", type=float, default=5000.0,
                    help="moving: goal for a cached tile's WANT -> TILE p99")
    ap.add_argument("--loop-over-50", type=int, default=0,
                    help="moving: event-loop iterations over 50 ms of the loop's own work or "
                    "waits allowed (goal 0)")
    args = ap.parse_args()
    lo, _, hi = args.levels.partition("-")
    if not lo.isdigit() or not (hi or lo).isdigit() or int(lo) > int(hi or lo) or int(hi or lo) > 20:
        ap.error("--levels: expected A-B with 0 <= A <= B <= 20")
    args.levels = list(range(int(lo), int(hi or lo) + 1))
    if args.sessions < 1 or args.region_deg <= 0 or args.speed_dps <= 0:
        ap.error("--sessions, --region-deg and --speed-dps must be positive")
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
    unknown = which - {"idle", "big", "slow", "inject", "corridor", "moving"}
    if unknown:
        ap.error("unknown scenario %s" % ",".join(sorted(unknown)))

    # the baseline after the tile pool's start-up prefault ([engine] prefault): the daemon
    # faults in cache_mb within seconds of start, which is not growth
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            if stats_now(args).get("memory.pool.prefault_left", 0) == 0:
                break
        except (OSError, RuntimeError):
            pass
        time.sleep(0.2)
    rss0 = rss_kib(args.pid) if args.pid else None
    probes = ProbeProcess(args)
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
    if "corridor" in which:
        f = run_phase("corridor", probes, lambda: scenario_corridor(args), rss0, args, goals)
        summary["corridor"] = f
        for label in ("corridor", "planet_l11"):
            a = f[label]
            if a["answer"] != "limit" or a["ms"] > args.p99_ms:
                goals.append("corridor: %s answered %s in %.1f ms (expected limit within %g ms)"
                             % (label, a["answer"], a["ms"], args.p99_ms))
    if "moving" in which:
        n = args.sessions
        f = run_phase("moving", probes, lambda: scenario_moving(args, n, seconds), rss0, args,
                      goals)
        summary["moving"] = f
        if f.get("error"):
            goals.append("moving: %s" % f["error"])
        else:
            if f["tile_p99_ms"] is None or f["tile_p99_ms"] > args.tile_p99_ms:
                goals.append("moving: tile p99 %s ms > %g ms" % (f["tile_p99_ms"],
                                                                 args.tile_p99_ms))
            if f["errors"] or f["tile_fails"]:
                goals.append("moving: %d TILE_FAIL, errors %s" % (f["tile_fails"], f["errors"]))
            # The loop's own stalls: iterations over 50 ms in which it worked (its CPU) or
            # waited (a voluntary switch: a lock, a blocking call). Those it spent runnable
            # but off the CPU (preempted: this harness shares the machine) are reported.
            own = f["loop.over_50ms.work"] + f["loop.over_50ms.blocked"]
            if own > args.loop_over_50:
                goals.append("moving: %d event-loop iterations over 50 ms of its own work or "
                             "waits" % own)
            if f["hello_after_close_ms"] > args.p99_ms:
                goals.append("moving: HELLO right after %d sessions closed took %.1f ms" %
                             (n, f["hello_after_close_ms"]))
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
