"""cmproto: the few clipmap protocol messages the load/attack harness needs, written from
docs/PROTOCOL.md alone (not from the project's C client), so the harness checks the daemon
against the document. Python 3 standard library only.

Frames: 12-byte header (magic "CLMP", version 4, flags 0, u16 type, u32 payload length),
little-endian. Encoders return whole frames (bytes); decoders take a payload.
"""
import socket
import struct
import time

MAGIC = b"CLMP"
VERSION = 4
HDR = 12

HELLO, HELLO_OK, BYE, ERROR = 1, 2, 3, 4
LIST_PLANETS, PLANETS, OPEN, OPENED = 16, 17, 18, 19
WANT, TILE, TILE_FAIL = 32, 33, 34
STATS_REQ, STATS = 48, 49
PREFETCH, PREFETCH_PROGRESS = 64, 65
CLASS_VISIBLE, CLASS_PREFETCH, CLASS_BULK = 1, 2, 3

ERROR_CODES = {0: "none", 1: "protocol", 2: "version", 3: "auth", 4: "state", 5: "not-found",
               6: "limit", 7: "invalid", 8: "unavailable", 9: "busy", 10: "internal",
               11: "shutdown"}


def header(mtype, length):
    """A frame header announcing `length` payload bytes (the body may never follow)."""
    return MAGIC + struct.pack("<BBHI", VERSION, 0, mtype, length)


def frame(mtype, payload=b""):
    return header(mtype, len(payload)) + payload


def _str(s):
    b = s.encode("utf-8") if isinstance(s, str) else s
    return struct.pack("<H", len(b)) + b


def hello(name="cmproto/1", token=b"", codecs=0, ver_min=VERSION, ver_max=VERSION):
    return frame(HELLO, struct.pack("<BBI", ver_min, ver_max, codecs) + _str(token) + _str(name))


def bye():
    return frame(BYE)


def stats_req(req=1):
    return frame(STATS_REQ, struct.pack("<I", req))


def open_planet(name, req=1):
    return frame(OPEN, struct.pack("<I", req) + _str(name))


def list_planets(req=1):
    return frame(LIST_PLANETS, struct.pack("<I", req))


def prefetch_path(job, planet, lmin, lmax, width, points, layers=0):
    """PREFETCH of a corridor `width` metres wide along (lon, lat) points."""
    p = struct.pack("<I", job) + _str(planet) + struct.pack("<QBBBdI", layers, 2, lmin, lmax,
                                                           width, len(points))
    for lon, lat in points:
        p += struct.pack("<2d", lon, lat)
    return frame(PREFETCH, p)


def prefetch_bbox(job, planet, lmin, lmax, west, south, east, north, layers=0):
    p = struct.pack("<I", job) + _str(planet) + struct.pack("<QBBB4d", layers, 1, lmin, lmax,
                                                           west, south, east, north)
    return frame(PREFETCH, p)


def want(planet_id, seq, entries, lon=0.0, lat=0.0, alt=1e6, vel=(0.0, 0.0, 0.0)):
    """entries: (layer, cls, lx, ly, x, y) tuples, most wanted first."""
    p = struct.pack("<II4d2d", planet_id, seq, lon, lat, alt, *vel)
    p += struct.pack("<I", len(entries))
    for layer, cls, lx, ly, x, y in entries:
        p += struct.pack("<BBBBII", layer, cls, lx, ly, x, y)
    return frame(WANT, p)


class Reader:
    """Cuts a byte stream into (type, payload) frames."""

    def __init__(self):
        self.buf = b""

    def feed(self, data):
        self.buf += data

    def next(self):
        if len(self.buf) < HDR:
            return None
        if self.buf[:4] != MAGIC:
            raise ValueError("bad magic from the server")
        _, _, mtype, length = struct.unpack_from("<BBHI", self.buf, 4)
        if len(self.buf) < HDR + length:
            return None
        payload = self.buf[HDR:HDR + length]
        self.buf = self.buf[HDR + length:]
        return mtype, payload


class Skimmer:
    """Cuts a socket's byte stream into frames without keeping tile texels: a TILE's payload
    is read up to its 44-byte header and the rest received into a scratch buffer and
    dropped, so a client of many sessions costs one kernel copy per byte. Other frames are
    kept whole. pump() reads once and returns the frames it completed as (type, payload
    head, length); None at end of stream."""

    def __init__(self, scratch=None):
        self.scratch = scratch if scratch is not None else bytearray(1 << 20)
        self.part = bytearray()
        self.mtype = None  # None: reading a header
        self.length = self.head = self.skip = 0

    def pump(self, s):
        n = s.recv_into(self.scratch)
        if n == 0:
            return None
        mv = memoryview(self.scratch)
        out, i = [], 0
        while i < n:
            if self.skip:
                k = min(self.skip, n - i)
                self.skip -= k
                i += k
                if self.skip == 0:
                    out.append((self.mtype, bytes(self.part), self.length))
                    self.part.clear()
                    self.mtype = None
                continue
            need = (HDR if self.mtype is None else self.head) - len(self.part)
            k = min(need, n - i)
            self.part += mv[i:i + k]
            i += k
            if k < need:
                break
            if self.mtype is None:
                if self.part[:4] != MAGIC:
                    raise ValueError("bad magic from the server")
                _, _, self.mtype, self.length = struct.unpack_from("<BBHI", self.part, 4)
                self.head = min(self.length, 44) if self.mtype == TILE else self.length
                self.part.clear()
                need = self.head
            if self.mtype is not None and len(self.part) == self.head:
                self.skip = self.length - self.head
                if self.skip == 0:
                    out.append((self.mtype, bytes(self.part), self.length))
                    self.part.clear()
                    self.mtype = None
        mv.release()
        return out


def _rd_str(p, off):
    (n,) = struct.unpack_from("<H", p, off)
    return p[off + 2:off + 2 + n].decode("utf-8"), off + 2 + n


def decode_hello_ok(p):
    version, codecs, session, max_want, max_rate, max_pending, max_frame = \
        struct.unpack_from("<BIQIIQI", p, 0)
    name, _ = _rd_str(p, 33)
    return {"version": version, "codecs": codecs, "session": session, "max_want": max_want,
            "max_rate": max_rate, "max_pending": max_pending, "max_frame": max_frame,
            "name": name}


def decode_planet(p, off=0):
    """One planet record (PLANETS, OPENED): (dict, offset after it)."""
    name, off = _rd_str(p, off)
    _, off = _rd_str(p, off)
    a, f, tile_size, max_level, nlayers = struct.unpack_from("<ddIBH", p, off)
    off += 23
    layers = []
    for _ in range(nlayers):
        lname, off = _rd_str(p, off)
        fmt, node, normal_of = struct.unpack_from("<BQB", p, off)  # normal_of: version 4
        off += 10
        layers.append({"name": lname, "format": fmt, "node": node, "normal_of": normal_of})
    off += 8 + 8 + 3 + 1 + 8 + 1  # the look: air density, height, colour, sea, sea level, mask
    rows, cols = struct.unpack_from("<HH", p, off)  # the sea's lattice (version 3)
    off += 4 + 2 * rows * cols
    return {"name": name, "a": a, "f": f, "tile_size": tile_size, "max_level": max_level,
            "layers": layers}, off


def decode_planets(p):
    _, count = struct.unpack_from("<IH", p, 0)
    off, out = 6, []
    for _ in range(count):
        pl, off = decode_planet(p, off)
        out.append(pl)
    return out


def decode_opened(p):
    """(planet_id, planet record)."""
    _, pid = struct.unpack_from("<II", p, 0)
    return pid, decode_planet(p, 8)[0]


def tile_key(p):
    """(planet_id, (layer, lx, ly, x, y)) from a TILE payload's first 24 bytes."""
    _, pid, layer, lx, ly = struct.unpack_from("<IIBBB", p, 0)
    x, y = struct.unpack_from("<II", p, 16)
    return pid, (layer, lx, ly, x, y)


def tile_fail_key(p):
    _, pid, layer, lx, ly, x, y = struct.unpack_from("<IIBBBII", p, 0)
    return pid, (layer, lx, ly, x, y)


def decode_error(p):
    code, ref_type, ref_id = struct.unpack_from("<HHI", p, 0)
    msg, _ = _rd_str(p, 8)
    return {"code": code, "name": ERROR_CODES.get(code, "internal"), "ref_type": ref_type,
            "ref_id": ref_id, "message": msg}


def decode_stats(p):
    req, count = struct.unpack_from("<IH", p, 0)
    off, out = 6, {}
    for _ in range(count):
        key, off = _rd_str(p, off)
        kind = p[off]
        off += 1
        if kind == 1:
            (v,) = struct.unpack_from("<Q", p, off)
            off += 8
        elif kind == 2:
            (v,) = struct.unpack_from("<d", p, off)
            off += 8
        else:
            v, off = _rd_str(p, off)
        out[key] = v
    return req, out


def connect(addr, timeout=5.0, source=None):
    """addr: a Unix socket path, or (host, port). source: a local address for TCP."""
    if isinstance(addr, str):
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    else:
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        if source:
            s.bind((source, 0))
    s.settimeout(timeout)
    s.connect(addr)
    return s


def recv_frame(s, reader, deadline):
    """The next frame, or None at end of stream; socket.timeout past deadline (monotonic)."""
    while True:
        f = reader.next()
        if f:
            return f
        left = deadline - time.monotonic()
        if left <= 0:
            raise socket.timeout("no frame before the deadline")
        s.settimeout(left)
        data = s.recv(65536)
        if not data:
            return None
        reader.feed(data)


def handshake(addr, token=b"", name="cmproto/1", timeout=5.0, source=None):
    """Connects and says HELLO. Returns (socket, reader, HELLO_OK dict, seconds taken);
    raises RuntimeError naming the ERROR the server sent instead."""
    t0 = time.monotonic()
    s = connect(addr, timeout, source)
    try:
        s.sendall(hello(name=name, token=token))
        r = Reader()
        f = recv_frame(s, r, t0 + timeout)
        if f is None:
            raise RuntimeError("closed before HELLO_OK")
        if f[0] == ERROR:
            e = decode_error(f[1])
            raise RuntimeError("ERROR %s: %s" % (e["name"], e["message"]))
        if f[0] != HELLO_OK:
            raise RuntimeError("frame type %d instead of HELLO_OK" % f[0])
        return s, r, decode_hello_ok(f[1]), time.monotonic() - t0
    except BaseException:
        s.close()
        raise
