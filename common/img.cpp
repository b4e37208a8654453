// img — the only C++ that touches OpenImageIO; see img.h. Every extern "C" function catches
// everything: OIIO reports most failures by return value, but std::bad_alloc and friends must
// not unwind into C. An img_cache wraps a private OIIO::ImageCache (thread-safe; OIIO keeps
// error messages per thread, so concurrent readers do not see each other's errors). The
// cache is reference counted (planets share one) and remembers, per file name, the version
// (size, mtime, inode...) its users last saw, so a changed file is invalidated once.
#include "errbuf.h"
#include "img.h"
#include "img_tiff.h"

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/fmath.h>
#include <OpenImageIO/imagecache.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fcntl.h>
#include <memory>
#include <mutex>
#include <new>
#include <string>
#include <unordered_map>
#include <sys/stat.h>
#include <unistd.h>
#include <vector>

using namespace OIIO;

struct img_cache {
	ImageCache *ic;
	size_t max_mb;
	std::atomic<int> refs{ 1 };
	std::mutex mu; // guards versions and broken
	std::unordered_map<std::string, std::string> versions;
	// Files a read failed on, with the message: OIIO serves a tile it could not read as
	// black from then on, without an error, so every later read of the file fails here
	// until the next img_cache_set_version (a load or reload) or img_cache_invalidate.
	std::unordered_map<std::string, std::string> broken;
	std::atomic<int> nbroken{ 0 };
};

namespace {

// err_set for an OpenImageIO message b: fmt has two %s, for a and for b's first line.
void oiio_err(char *err, const char *fmt, const char *a, const std::string &b)
{
	if (!err)
		return;
	// OIIO repeats one failure at several layers, one line each: the first says it best.
	std::string m = b.substr(0, b.find('\n'));
	while (!m.empty() && m.back() == ' ')
		m.pop_back();
	if (m.empty())
		m = "unknown OpenImageIO error";
	err_set(err, fmt, a, m.c_str());
}

[[noreturn]] void oom()
{
	std::fprintf(stderr, "clipmap: out of memory in OpenImageIO\n");
	std::abort();
}

// Runs f (returning 0 or -errno) under the extern "C" contract: running out of memory aborts,
// any other exception is -EIO with err naming path. Nothing unwinds into C.
template <typename F> int guarded(const char *path, char *err, F f)
{
	try {
		return f();
	} catch (const std::bad_alloc &) {
		oom();
	} catch (const std::exception &e) {
		oiio_err(err, "%s: %s", path, e.what());
		return -EIO;
	}
}

TypeDesc to_desc(enum img_type t)
{
	switch (t) {
	case IMG_U8:
		return TypeDesc::UINT8;
	case IMG_U16:
		return TypeDesc::UINT16;
	case IMG_I16:
		return TypeDesc::INT16;
	case IMG_F32:
		return TypeDesc::FLOAT;
	default:
		return TypeDesc::UNKNOWN;
	}
}

enum img_type from_desc(TypeDesc d)
{
	switch (d.basetype) {
	case TypeDesc::UINT8:
		return IMG_U8;
	case TypeDesc::UINT16:
		return IMG_U16;
	case TypeDesc::INT16:
		return IMG_I16;
	case TypeDesc::HALF:
	case TypeDesc::FLOAT:
	case TypeDesc::DOUBLE:
		return IMG_F32;
	default:
		return IMG_NONE;
	}
}

void fill_info(const ImageSpec &s, struct img_info *out)
{
	std::memset(out, 0, sizeof *out);
	out->width = s.width;
	out->height = s.height;
	out->channels = s.nchannels;
	out->type = from_desc(s.format);
	snprintf(out->format, sizeof out->format, "%s", s.format.c_str());
	out->mip_levels = 1;
	out->tiled = s.tile_width > 0;
	out->tile_width = s.tile_width;
	out->tile_height = s.tile_height;
}

// -ENOENT when the file is not there, else the given code.
int missing_or(const char *path, int code)
{
	struct stat st;
	return stat(path, &st) != 0 && errno == ENOENT ? -ENOENT : code;
}

std::string ext_of(const char *path)
{
	const char *dot = std::strrchr(path, '.');
	const char *slash = std::strrchr(path, '/');
	if (!dot || (slash && dot < slash))
		return "";
	std::string e(dot + 1);
	for (char &ch : e)
		ch = (char)std::tolower((unsigned char)ch);
	return e;
}

// Picks the OIIO format for a path and checks the type fits it. Returns 0 or -EINVAL.
int pick_format(const char *path, enum img_type type, bool tiled, const char **fmt, char *err)
{
	std::string e = ext_of(path);
	bool ok = false;
	if (e == "png" && !tiled) {
		*fmt = "png";
		ok = type == IMG_U8 || type == IMG_U16;
	} else if (e == "tif" || e == "tiff") {
		*fmt = "tiff";
		ok = type != IMG_NONE;
	} else if (e == "exr" && !tiled) {
		*fmt = "openexr";
		ok = type == IMG_F32;
	} else {
		err_set(err, "%s: cannot write a%s image with extension \"%s\" "
			"(use .png, .tif or .exr)", path, tiled ? " tiled" : "n",
			e.c_str());
		return -EINVAL;
	}
	if (!ok) {
		err_set(err, "%s: %s cannot hold %s pixels", path, *fmt,
			to_desc(type).c_str());
		return -EINVAL;
	}
	return 0;
}

// fsync a file we just wrote (OIIO closed it), so the rename publishes complete data.
int sync_file(const char *path)
{
	int fd = open(path, O_RDONLY | O_CLOEXEC);
	if (fd < 0)
		return -errno;
	int rc = fsync(fd) ? -errno : 0;
	if (close(fd) && rc == 0)
		rc = -errno;
	return rc;
}

int publish(const std::string &tmp, const char *path, char *err)
{
	int rc = sync_file(tmp.c_str());
	if (rc == 0 && rename(tmp.c_str(), path) != 0)
		rc = -errno;
	if (rc) {
		oiio_err(err, "%s: %s", path, std::string("cannot publish: ") + std::strerror(-rc));
		unlink(tmp.c_str());
	}
	return rc;
}

// The spec of a file this module writes: straight alpha; tiled (tile > 0) files zip-compressed,
// and BigTIFF when they could pass classic TIFF's 32-bit offsets.
ImageSpec out_spec(int width, int height, int channels, enum img_type type, int tile, bool mip,
		   const char *desc)
{
	ImageSpec spec(width, height, channels, to_desc(type));
	spec.attribute("oiio:UnassociatedAlpha", 1); // pixels are straight alpha: store as given
	if (tile > 0) {
		spec.tile_width = spec.tile_height = tile;
		spec.attribute("compression", "zip");
		// Classic TIFF offsets are 32-bit: a pyramid (4/3 of the base) near 4 GiB
		// uncompressed needs BigTIFF (zip may not shrink noise-like data).
		double bytes = (double)width * height * channels * (double)img_type_bytes(type);
		if (bytes * (mip ? 4.0 / 3.0 : 1.0) > 3.5e9)
			spec.attribute("tiff:bigtiff", 1);
	}
	if (desc)
		spec.attribute("ImageDescription", desc);
	return spec;
}

int write_impl(const char *path, int width, int height, int channels, enum img_type type,
	       const void *pixels, int tile, bool mip, const char *desc, char *err)
{
	if (width <= 0 || height <= 0 || channels <= 0 || !pixels) {
		err_set(err, "%s: bad image size %dx%dx%d", path, width, height,
			channels);
		return -EINVAL;
	}
	const char *fmt = nullptr;
	int rc = pick_format(path, type, tile > 0, &fmt, err);
	if (rc)
		return rc;
	std::string tmp = std::string(path) + ".tmp";
	ImageSpec spec = out_spec(width, height, channels, type, tile, mip, desc);
	if (fmt == std::string("openexr"))
		spec.attribute("compression", "zip");
	if (mip) {
		// make_texture writes a tiled, box-filtered MIP pyramid.
		ImageBuf src(spec, const_cast<void *>(pixels));
		ImageSpec config = spec;
		config.attribute("maketx:filtername", "box");
		config.attribute("maketx:fileformatname", fmt);
		config.attribute("maketx:highlightcomp", 0);
		if (!ImageBufAlgo::make_texture(ImageBufAlgo::MakeTxTexture, src, tmp, config)) {
			oiio_err(err, "%s: cannot write: %s", path, OIIO::geterror());
			unlink(tmp.c_str());
			return -EIO;
		}
		return publish(tmp, path, err);
	}
	std::unique_ptr<ImageOutput> out = ImageOutput::create(fmt);
	if (!out) {
		oiio_err(err, "%s: %s", path, OIIO::geterror());
		return -EIO;
	}
	if (!out->open(tmp, spec) || !out->write_image(to_desc(type), pixels)) {
		oiio_err(err, "%s: cannot write: %s", path, out->geterror());
		out->close();
		unlink(tmp.c_str());
		return -EIO;
	}
	if (!out->close()) {
		oiio_err(err, "%s: cannot write: %s", path, out->geterror());
		unlink(tmp.c_str());
		return -EIO;
	}
	return publish(tmp, path, err);
}

// Copies [x0, x1) × [y0, y1), channels [chb, che), straight out of the cached tiles when they
// hold `td` pixels already: get_pixels' general conversion path runs at about half of memcpy
// speed, this at nearly all of it. Returns true when done; false when not applicable (a
// conversion, a missing tile, an unexpected layout) — the caller then uses get_pixels, which
// also produces any error message.
bool read_from_tiles(ImageCache *ic, ustring name, int m, int x0, int x1, int y0, int y1, int chb,
		     int che, TypeDesc td, char *dst, size_t ystride)
{
	const ImageSpec *spec = ic->imagespec(name, 0, m);
	if (!spec || spec->depth != 1 || x0 < spec->x || x1 > spec->x + spec->width ||
	    y0 < spec->y || y1 > spec->y + spec->height || che > spec->nchannels)
		return false;
	int tw = spec->tile_width > 0 ? spec->tile_width : spec->width;
	int th = spec->tile_height > 0 ? spec->tile_height : spec->height;
	size_t bytes = td.size(), outpx = (size_t)(che - chb) * bytes;
	for (int ty = y0 - (y0 - spec->y) % th; ty < y1; ty += th) {
		for (int tx = x0 - (x0 - spec->x) % tw; tx < x1; tx += tw) {
			ImageCache::Tile *t = ic->get_tile(name, 0, m, tx, ty, 0);
			if (!t)
				return false;
			TypeDesc fmt;
			const char *p = (const char *)ic->tile_pixels(t, fmt);
			ROI roi = ic->tile_roi(t);
			if (!p || fmt != td || roi.xbegin != tx || roi.ybegin != ty ||
			    roi.width() != tw || roi.height() != th || roi.chbegin != 0 ||
			    roi.chend < che) {
				ic->release_tile(t);
				return false;
			}
			size_t spx = (size_t)roi.nchannels() * bytes;
			int xa = std::max(x0, tx), xb = std::min(x1, tx + tw);
			int ya = std::max(y0, ty), yb = std::min(y1, ty + th);
			for (int y = ya; y < yb; y++) {
				const char *src = p + ((size_t)(y - ty) * tw + (size_t)(xa - tx)) * spx +
						  (size_t)chb * bytes;
				char *d = dst + (size_t)(y - y0) * ystride + (size_t)(xa - x0) * outpx;
				if (outpx == spx) {
					std::memcpy(d, src, (size_t)(xb - xa) * spx);
				} else {
					for (int i = 0; i < xb - xa; i++)
						std::memcpy(d + i * outpx, src + i * spx, outpx);
				}
			}
			ic->release_tile(t);
		}
	}
	return true;
}

} // namespace

extern "C" size_t img_type_bytes(enum img_type t)
{
	switch (t) {
	case IMG_U8:
		return 1;
	case IMG_U16:
	case IMG_I16:
		return 2;
	case IMG_F32:
		return 4;
	default:
		return 0;
	}
}

extern "C" struct img_cache *img_cache_create(size_t max_mb)
{
	try {
		ImageCache *ic = ImageCache::create(false);
		if (!ic)
			return nullptr;
		ic->attribute("max_memory_MB", (float)(max_mb ? max_mb : 1));
		ic->attribute("automip", 1);
		ic->attribute("autotile", 0); // untiled images: one tile (PNG/JPEG decode serially)
		ic->attribute("max_open_files", 100);
		ic->attribute("failure_retries", 0);
		ic->attribute("unassociatedalpha", 1); // tiles are straight alpha: keep files' own
		img_cache *c = new img_cache;
		c->ic = ic;
		c->max_mb = max_mb ? max_mb : 1;
		return c;
	} catch (const std::bad_alloc &) {
		oom();
	} catch (...) {
		return nullptr;
	}
}

extern "C" struct img_cache *img_cache_ref(struct img_cache *c)
{
	if (c)
		c->refs.fetch_add(1, std::memory_order_relaxed);
	return c;
}

extern "C" void img_cache_unref(struct img_cache *c)
{
	if (!c || c->refs.fetch_sub(1, std::memory_order_acq_rel) != 1)
		return;
	try {
		c->ic->geterror(true);
		ImageCache::destroy(c->ic, true);
	} catch (...) {
	}
	delete c;
}

extern "C" int img_cache_info(struct img_cache *c, const char *path, struct img_info *out,
			      char err[256])
{
	return guarded(path, err, [&] {
		ImageSpec spec;
		ustring name(path);
		if (!c->ic->get_imagespec(name, spec, 0, 0, true)) {
			oiio_err(err, "%s: %s", path, c->ic->geterror());
			return missing_or(path, -EIO);
		}
		fill_info(spec, out);
		int levels = 1;
		if (c->ic->get_image_info(name, 0, 0, ustring("miplevels"), TypeInt, &levels) &&
		    levels > 0)
			out->mip_levels = levels;
		c->ic->geterror(true);
		return 0;
	});
}

extern "C" int img_cache_level_size(struct img_cache *c, const char *path, int miplevel,
				    int *width, int *height, char err[256])
{
	return guarded(path, err, [&] {
		ImageSpec spec;
		if (!c->ic->get_imagespec(ustring(path), spec, 0, miplevel, false)) {
			oiio_err(err, "%s: %s", path, c->ic->geterror());
			if (miplevel > 0)
				return -EINVAL;
			return missing_or(path, -EIO);
		}
		*width = spec.width;
		*height = spec.height;
		return 0;
	});
}

static int cache_read(struct img_cache *c, const char *path, int miplevel, int x0, int x1, int y0,
	       int y1, int chbegin, int chend, TypeDesc td, size_t tbytes, void *dst,
	       size_t dst_stride, char *err);

extern "C" int img_cache_read(struct img_cache *c, const char *path, int miplevel, int x0, int x1,
			      int y0, int y1, int chbegin, int chend, enum img_type type, void *dst,
			      size_t dst_stride, char err[256])
{
	TypeDesc td = to_desc(type);
	if (x1 <= x0 || y1 <= y0 || chbegin < 0 || chend <= chbegin || td == TypeDesc::UNKNOWN) {
		err_set(err, "%s: bad region [%d,%d)x[%d,%d) channels [%d,%d)", path,
			x0, x1, y0, y1, chbegin, chend);
		return -EINVAL;
	}
	return guarded(path, err, [&] {
		if (c->nbroken.load(std::memory_order_acquire)) {
			std::lock_guard<std::mutex> lk(c->mu);
			auto it = c->broken.find(path);
			if (it != c->broken.end()) {
				err_set(err, "%s", it->second.c_str());
				return -EIO;
			}
		}
		int rc = cache_read(c, path, miplevel, x0, x1, y0, y1, chbegin, chend, td,
				    img_type_bytes(type), dst, dst_stride, err);
		if (rc == -EIO) {
			std::lock_guard<std::mutex> lk(c->mu);
			if (c->broken.emplace(path, err ? err : "read failed").second)
				c->nbroken.fetch_add(1, std::memory_order_release);
		}
		return rc;
	});
}

namespace {
bool forget_broken(struct img_cache *c, const char *path)
{
	std::lock_guard<std::mutex> lk(c->mu);
	if (!c->broken.erase(path))
		return false;
	c->nbroken.fetch_sub(1, std::memory_order_release);
	return true;
}
} // namespace

static int cache_read(struct img_cache *c, const char *path, int miplevel, int x0, int x1, int y0,
	       int y1, int chbegin, int chend, TypeDesc td, size_t tbytes, void *dst,
	       size_t dst_stride, char *err)
{
	{
		size_t px = tbytes * (size_t)(chend - chbegin);
		size_t row = dst_stride ? dst_stride : px * (size_t)(x1 - x0);
		ustring name(path);
		if (c->ic->has_error())
			c->ic->geterror(true); // stale: not this read's
		if (read_from_tiles(c->ic, name, miplevel, x0, x1, y0, y1, chbegin, chend, td,
				    (char *)dst, row)) {
			// An automip tile made from unreadable tiles comes back whole, with an
			// error message: a failure, not zeros.
			if (!c->ic->has_error())
				return 0;
			oiio_err(err, "%s: %s", path, c->ic->geterror());
			return -EIO;
		}
		stride_t xs = (stride_t)px, ys = (stride_t)row;
		if (!c->ic->get_pixels(name, 0, miplevel, x0, x1, y0, y1, 0, 1, chbegin,
				       chend, td, dst, xs, ys, AutoStride, chbegin, chend)) {
			oiio_err(err, "%s: %s", path, c->ic->geterror());
			return missing_or(path, -EIO);
		}
		// A tile that cannot be read (a file cut short) comes back black with success
		// and an error message: that is a failure, not zeros.
		std::string e = c->ic->geterror();
		if (!e.empty()) {
			oiio_err(err, "%s: %s", path, e);
			return -EIO;
		}
		return 0;
	}
}

extern "C" void img_cache_invalidate(struct img_cache *c, const char *path)
{
	try {
		forget_broken(c, path);
		c->ic->invalidate(ustring(path), true);
	} catch (...) {
	}
}

extern "C" bool img_cache_set_version(struct img_cache *c, const char *path, const void *version,
				      size_t n)
{
	try {
		std::string v(static_cast<const char *>(version), n);
		bool changed, first;
		{
			std::lock_guard<std::mutex> lk(c->mu);
			auto it = c->versions.find(path);
			first = it == c->versions.end();
			changed = !first && it->second != v;
			if (first)
				c->versions.emplace(path, std::move(v));
			else if (changed)
				it->second = std::move(v);
		}
		// First sight: whatever was cached under this name before (read without a version)
		// goes only if OIIO sees a newer mtime; a version change goes unconditionally (mtimes
		// in whole seconds miss a file rewritten within the second).
		// A file that failed a read is retried from scratch by the next load (a reload after
		// the operator fixed it): OIIO still holds its unreadable tiles as black.
		bool was_broken = forget_broken(c, path);
		if (first || changed || was_broken)
			c->ic->invalidate(ustring(path), changed || was_broken);
		return changed;
	} catch (const std::bad_alloc &) {
		oom();
	} catch (...) {
		return false;
	}
}

extern "C" void img_cache_get_stats(struct img_cache *c, struct img_cache_stats *out)
{
	*out = img_cache_stats{};
	out->max_bytes = (uint64_t)c->max_mb << 20;
	try {
		long long mem = 0;
		int files = 0, created = 0, current = 0;
		c->ic->getattribute("stat:cache_memory_used", TypeDesc::INT64, &mem);
		c->ic->getattribute("total_files", TypeDesc::INT, &files);
		c->ic->getattribute("stat:open_files_created", TypeDesc::INT, &created);
		c->ic->getattribute("stat:open_files_current", TypeDesc::INT, &current);
		out->memory_used = mem > 0 ? (uint64_t)mem : 0;
		out->files = files;
		out->opens = created;
		out->open_now = current;
	} catch (...) {
	}
}

extern "C" int img_write(const char *path, int width, int height, int channels,
			 enum img_type type, const void *pixels, char err[256])
{
	return guarded(path, err, [&] {
		return write_impl(path, width, height, channels, type, pixels, 0, false, nullptr, err);
	});
}

extern "C" int img_write_tiled(const char *path, int width, int height, int channels,
			       enum img_type type, const void *pixels, int tile, bool mip,
			       char err[256])
{
	return img_write_tiled_desc(path, width, height, channels, type, pixels, tile, mip,
				    nullptr, err);
}

extern "C" int img_write_tiled_desc(const char *path, int width, int height, int channels,
				    enum img_type type, const void *pixels, int tile, bool mip,
				    const char *description, char err[256])
{
	if (tile <= 0 || tile % 16) {
		err_set(err, "%s: tile size %d is not a positive multiple of 16",
			path, tile);
		return -EINVAL;
	}
	return guarded(path, err, [&] {
		return write_impl(path, width, height, channels, type, pixels, tile, mip,
				  description, err);
	});
}

extern "C" int img_cache_description(struct img_cache *c, const char *path, char *buf, size_t n,
				     char err[256])
{
	if (n)
		buf[0] = 0;
	return guarded(path, err, [&] {
		ImageSpec spec;
		if (!c->ic->get_imagespec(ustring(path), spec, 0, 0, false)) {
			oiio_err(err, "%s: %s", path, c->ic->geterror());
			return missing_or(path, -EIO);
		}
		std::string d = spec.get_string_attribute("ImageDescription");
		if (d.empty())
			return -ENODATA;
		if (n)
			snprintf(buf, n, "%s", d.c_str());
		return 0;
	});
}

extern "C" int img_read(const char *path, enum img_type type, void **pixels,
			struct img_info *info, char err[256])
{
	*pixels = nullptr;
	return guarded(path, err, [&] {
		ImageSpec config;
		config.attribute("oiio:UnassociatedAlpha", 1);
		std::unique_ptr<ImageInput> in = ImageInput::open(path, &config);
		if (!in) {
			oiio_err(err, "%s: %s", path, OIIO::geterror());
			return missing_or(path, -EIO);
		}
		const ImageSpec &spec = in->spec();
		struct img_info inf;
		fill_info(spec, &inf);
		if (type == IMG_NONE)
			type = inf.type != IMG_NONE ? inf.type : IMG_F32;
		size_t n = (size_t)spec.width * (size_t)spec.height * (size_t)spec.nchannels *
			   img_type_bytes(type);
		void *buf = std::malloc(n ? n : 1);
		if (!buf)
			oom();
		if (!in->read_image(0, 0, 0, spec.nchannels, to_desc(type), buf)) {
			oiio_err(err, "%s: %s", path, in->geterror());
			std::free(buf);
			return -EIO;
		}
		in->close();
		if (info)
			*info = inf;
		*pixels = buf;
		return 0;
	});
}

// ---- streaming tiled writer (img_tiled_*) ----
//
// make_texture (OIIO 2.4, maketexture.cpp, filter "box", forcefloat) keeps the top level as
// float (the stored type converted, normalised), and computes each coarser level in float
// from the float level above: resize_block_2pass (0.5·(a+b) across, then 0.5·(r0+r1) down)
// when both sides of the level above are even, otherwise resize_block_ (bilinear sample at
// each destination pixel's centre, clamped at the edges). The cascade below repeats exactly
// those float operations, row by row: destination row y needs at most the two newest rows of
// the level above, so each level keeps a two-row window. Levels ≥ 1 are converted to the
// stored type as OIIO's ImageOutput would and spooled to a temporary file until level 0 is
// complete (TIFF stores the MIP levels in order).

struct img_tiled_out {
	struct level {
		int w = 0, h = 0;
		int rows_in = 0;  // rows of this level pushed into the cascade
		int rows_out = 0; // rows of the next level produced from this one
		bool two_pass = false;
		std::vector<float> ring;     // the two newest rows (slot r & 1)
		std::vector<int> xt;	     // bilinear: left texel per destination column
		std::vector<float> xf;	     // bilinear: its fraction
		std::vector<float> s0, s1;   // two-pass: the halved rows
		std::vector<float> next;     // the row produced for the next level
		std::vector<char> band;	     // this level (≥ 1) in the stored type, tile rows
		int band_y0 = 0, band_n = 0; // rows [band_y0, band_y0 + band_n) held in band
		off_t off = 0;		     // where this level starts in the spool
		size_t row_bytes = 0;
	};
	std::string path, tmp;
	std::unique_ptr<ImageOutput> out;
	TypeDesc td;
	int width = 0, height = 0, nch = 0, tile = 0;
	size_t px = 0;
	int rows = 0;
	bool mip = false;
	std::vector<level> lv;
	std::vector<float> f0;
	std::vector<char> tilebuf;
	int spool = -1;
	bool failed = false;
	bool has_nd = false; // img_tiled_set_nodata: averages skip nd samples
	float nd = 0;
};

namespace {

int spool_open(const std::string &path)
{
	std::string dir = ".";
	size_t slash = path.rfind('/');
	if (slash != std::string::npos)
		dir = slash ? path.substr(0, slash) : "/";
	int fd = open(dir.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
	if (fd >= 0)
		return fd;
	std::string t = path + ".mip.XXXXXX";
	std::vector<char> name(t.begin(), t.end());
	name.push_back(0);
	fd = mkostemp(name.data(), O_CLOEXEC);
	if (fd < 0)
		return -errno;
	unlink(name.data());
	return fd;
}

int write_all(int fd, const char *p, size_t n, off_t off)
{
	while (n) {
		ssize_t k = pwrite(fd, p, n, off);
		if (k < 0 && errno == EINTR)
			continue;
		if (k <= 0)
			return k < 0 ? -errno : -EIO;
		p += k, n -= (size_t)k, off += k;
	}
	return 0;
}

int read_all(int fd, char *p, size_t n, off_t off)
{
	while (n) {
		ssize_t k = pread(fd, p, n, off);
		if (k < 0 && errno == EINTR)
			continue;
		if (k <= 0)
			return k < 0 ? -errno : -EIO;
		p += k, n -= (size_t)k, off += k;
	}
	return 0;
}

int flush_band(img_tiled_out *o, img_tiled_out::level &L, char *err)
{
	if (!L.band_n)
		return 0;
	int rc = write_all(o->spool, L.band.data(), L.row_bytes * (size_t)L.band_n,
			   L.off + (off_t)L.row_bytes * L.band_y0);
	if (rc) {
		oiio_err(err, "%s: %s", o->path.c_str(),
			 std::string("cannot spool MIP levels: ") + std::strerror(-rc));
		return rc;
	}
	L.band_y0 += L.band_n;
	L.band_n = 0;
	return 0;
}

int push_row(img_tiled_out *o, size_t k, const float *row, char *err);

// The (w-weighted; NULL: equal) mean of the samples of v that are not nd, or nd when none
// is (with a weight); `all` when every one is valid (the plain average, bit for bit).
float mean_valid(const float *v, const float *w, int n, float nd, float all)
{
	float sum = 0, wsum = 0;
	bool any_nd = false;
	for (int i = 0; i < n; i++) {
		float wi = w ? w[i] : 1.0f;
		if (v[i] == nd) {
			any_nd = true;
			continue;
		}
		sum += wi * v[i];
		wsum += wi;
	}
	if (!any_nd)
		return all;
	return wsum > 0 ? sum / wsum : nd;
}

// Level k + 1's next row is in L.next: store it (stored type) and feed it on.
int emit_row(img_tiled_out *o, size_t k, char *err)
{
	img_tiled_out::level &L = o->lv[k], &D = o->lv[k + 1];
	int y = L.rows_out++;
	char *dst = D.band.data() + (size_t)(y - D.band_y0) * D.row_bytes;
	if (!convert_pixel_values(TypeFloat, L.next.data(), o->td, dst, D.w * o->nch)) {
		oiio_err(err, "%s: %s", o->path.c_str(), std::string("pixel conversion failed"));
		return -EIO;
	}
	D.band_n++;
	if (D.band_n == o->tile || y == D.h - 1) {
		int rc = flush_band(o, D, err);
		if (rc)
			return rc;
	}
	return push_row(o, k + 1, L.next.data(), err);
}

int push_row(img_tiled_out *o, size_t k, const float *row, char *err)
{
	img_tiled_out::level &L = o->lv[k];
	int nch = o->nch;
	size_t n = (size_t)L.w * nch;
	int r = L.rows_in++;
	std::memcpy(L.ring.data() + (size_t)(r & 1) * n, row, n * sizeof(float));
	if (k + 1 >= o->lv.size())
		return 0;
	const img_tiled_out::level &D = o->lv[k + 1];
	if (L.two_pass) {
		if (!(r & 1))
			return 0;
		const float *a = L.ring.data(), *b = a + n; // rows r - 1 (even), r (odd)
		size_t dn = (size_t)D.w * nch;
		for (size_t i = 0, x = 0; x < (size_t)D.w; x++) {
			for (int c = 0; c < nch; c++, i++) {
				size_t s = 2 * x * nch + c;
				L.s0[i] = 0.5f * (float)(a[s] + a[s + nch]);
				L.s1[i] = 0.5f * (float)(b[s] + b[s + nch]);
			}
		}
		for (size_t i = 0; i < dn; i++)
			L.next[i] = (float)(0.5f * (L.s0[i] + L.s1[i]));
		if (o->has_nd) { // a box holding nodata: the mean of its other samples, or nodata
			for (size_t i = 0, x = 0; x < (size_t)D.w; x++) {
				for (int c = 0; c < nch; c++, i++) {
					size_t s = 2 * x * nch + c;
					const float v[4] = { a[s], a[s + nch], b[s], b[s + nch] };
					L.next[i] = mean_valid(v, nullptr, 4, o->nd, L.next[i]);
				}
			}
		}
		return emit_row(o, k, err);
	}
	// resize_block_ / interppixel_NDC with WrapClamp, the same float expressions.
	float yscale = 1.0f / (float)D.h, yoffset = 0.0f, fy = 0.0f, fh = (float)L.h;
	while (L.rows_out < D.h) {
		int y = L.rows_out;
		float t = (y + 0.5f) * yscale + yoffset;
		float yy = fy + t * fh;
		yy -= 0.5f;
		int yt;
		float yfrac = floorfrac(yy, &yt);
		int ya = std::min(std::max(yt, 0), L.h - 1);
		int yb = std::min(std::max(yt + 1, 0), L.h - 1);
		if (yb > r)
			break;
		if (ya < r - 1) { // cannot happen: rows are consumed in order
			oiio_err(err, "%s: %s", o->path.c_str(),
				 std::string("MIP cascade out of order"));
			return -EIO;
		}
		const float *ra = L.ring.data() + (size_t)(ya & 1) * n;
		const float *rb = L.ring.data() + (size_t)(yb & 1) * n;
		for (int x = 0; x < D.w; x++) {
			int xa = L.xt[(size_t)x];
			int xb = std::min(xa + 1, L.w - 1);
			xa = std::max(xa, 0);
			xb = std::max(xb, 0);
			bilerp(ra + (size_t)xa * nch, ra + (size_t)xb * nch, rb + (size_t)xa * nch,
			       rb + (size_t)xb * nch, L.xf[(size_t)x], yfrac, nch,
			       L.next.data() + (size_t)x * nch);
			if (o->has_nd) {
				float s = L.xf[(size_t)x], s1 = 1 - s, t1 = 1 - yfrac;
				const float w[4] = { t1 * s1, t1 * s, yfrac * s1, yfrac * s };
				for (int c = 0; c < nch; c++) {
					const float v[4] = { ra[(size_t)xa * nch + c], ra[(size_t)xb * nch + c],
							     rb[(size_t)xa * nch + c], rb[(size_t)xb * nch + c] };
					float *r = L.next.data() + (size_t)x * nch + c;
					*r = mean_valid(v, w, 4, o->nd, *r);
				}
			}
		}
		int rc = emit_row(o, k, err);
		if (rc)
			return rc;
	}
	return 0;
}

void setup_levels(img_tiled_out *o)
{
	int w = o->width, h = o->height;
	off_t off = 0;
	for (;;) {
		img_tiled_out::level L;
		L.w = w, L.h = h;
		L.row_bytes = (size_t)w * o->px;
		if (!o->lv.empty()) {
			L.off = off;
			off += (off_t)L.row_bytes * h;
			L.band.resize(L.row_bytes * (size_t)std::min(o->tile, h));
		}
		o->lv.push_back(std::move(L));
		if (w == 1 && h == 1)
			break;
		w = w > 1 ? w / 2 : 1;
		h = h > 1 ? h / 2 : 1;
	}
	for (size_t k = 0; k + 1 < o->lv.size(); k++) {
		img_tiled_out::level &L = o->lv[k];
		const img_tiled_out::level &D = o->lv[k + 1];
		size_t n = (size_t)L.w * o->nch, dn = (size_t)D.w * o->nch;
		L.ring.resize(2 * n);
		L.next.resize(dn);
		L.two_pass = L.w % 2 == 0 && L.h % 2 == 0;
		if (L.two_pass) {
			L.s0.resize(dn);
			L.s1.resize(dn);
		} else {
			float xscale = 1.0f / (float)D.w, xoffset = 0.0f, fx = 0.0f;
			float fw = (float)L.w;
			L.xt.resize((size_t)D.w);
			L.xf.resize((size_t)D.w);
			for (int x = 0; x < D.w; x++) {
				float s = (x + 0.5f) * xscale + xoffset;
				float xx = fx + s * fw;
				xx -= 0.5f;
				L.xf[(size_t)x] = floorfrac(xx, &L.xt[(size_t)x]);
			}
		}
	}
	o->lv.back().ring.resize((size_t)o->lv.back().w * o->nch * 2);
	o->f0.resize((size_t)o->width * o->nch);
}

std::string date_now()
{
	time_t t = time(nullptr);
	struct tm tm;
	localtime_r(&t, &tm);
	char b[32];
	if (!strftime(b, sizeof b, "%Y:%m:%d %H:%M:%S", &tm))
		b[0] = 0;
	return b;
}

void tiled_discard(img_tiled_out *o)
{
	if (o->out)
		o->out->close();
	o->out.reset();
	unlink(o->tmp.c_str());
	if (o->spool >= 0)
		close(o->spool);
	o->spool = -1;
}

// Writes rows [y0, y0 + n) of a w-wide level (packed rows of the stored type). Whole tiles go
// through write_tiles (which may compress in parallel); tiles crossing the right or bottom
// edge go one by one from a zero-padded tile, so their padding is zeros (small once zipped,
// and the file does not depend on whatever a scratch buffer held before).
bool write_band(img_tiled_out *o, int w, int y0, int n, const char *data)
{
	int T = o->tile;
	size_t row = (size_t)w * o->px;
	int wfull = w / T * T, nfull = n / T * T;
	if (wfull && nfull &&
	    !o->out->write_tiles(0, wfull, y0, y0 + nfull, 0, 1, o->td, data, (stride_t)o->px,
				 (stride_t)row))
		return false;
	o->tilebuf.resize((size_t)T * T * o->px);
	for (int ty = 0; ty < n; ty += T) {
		int rows = std::min(T, n - ty);
		for (int tx = ty < nfull ? wfull : 0; tx < w; tx += T) {
			int cols = std::min(T, w - tx);
			std::memset(o->tilebuf.data(), 0, o->tilebuf.size());
			for (int y = 0; y < rows; y++)
				std::memcpy(o->tilebuf.data() + (size_t)y * T * o->px,
					    data + (size_t)(ty + y) * row + (size_t)tx * o->px,
					    (size_t)cols * o->px);
			if (!o->out->write_tile(tx, y0 + ty, 0, o->td, o->tilebuf.data()))
				return false;
		}
	}
	return true;
}

int tiled_open_impl(img_tiled_out *o, const char *path, int width, int height, int channels,
		    enum img_type type, int tile, bool mip, const char *desc, char *err)
{
	const char *fmt = nullptr;
	int rc = pick_format(path, type, true, &fmt, err);
	if (rc)
		return rc;
	o->path = path;
	o->tmp = o->path + ".tmp";
	o->td = to_desc(type);
	o->width = width, o->height = height, o->nch = channels, o->tile = tile;
	o->px = (size_t)channels * img_type_bytes(type);
	o->mip = mip;
	ImageSpec spec = out_spec(width, height, channels, type, tile, mip, desc);
	if (mip) { // what make_texture adds
		spec.attribute("planarconfig", "contig");
		spec.attribute("wrapmodes", "black,black");
		spec.attribute("DateTime", date_now());
		spec.attribute("textureformat", "Plain Texture");
		spec.attribute("fovcot", (float)width / (float)height);
		setup_levels(o);
		if (o->lv.size() > 1) {
			o->spool = spool_open(o->path);
			if (o->spool < 0) {
				oiio_err(err, "%s: %s", path,
					 std::string("cannot create a temporary file for the MIP "
						     "levels: ") + std::strerror(-o->spool));
				return -EIO;
			}
		}
	}
	o->out = ImageOutput::create(fmt);
	if (!o->out) {
		oiio_err(err, "%s: %s", path, OIIO::geterror());
		return -EIO;
	}
	if (!o->out->open(o->tmp, spec)) {
		oiio_err(err, "%s: cannot write: %s", path, o->out->geterror());
		tiled_discard(o);
		return -EIO;
	}
	return 0;
}

int tiled_rows_impl(img_tiled_out *o, const void *rows, int n, char *err)
{
	if (n <= 0 || o->rows + n > o->height || (n % o->tile && o->rows + n != o->height)) {
		err_set(err, "%s: %d rows at row %d of %d (tile %d)", o->path.c_str(),
			n, o->rows, o->height, o->tile);
		return -EINVAL;
	}
	const char *p = (const char *)rows;
	size_t row = (size_t)o->width * o->px;
	if (!write_band(o, o->width, o->rows, n, p)) {
		oiio_err(err, "%s: cannot write: %s", o->path.c_str(), o->out->geterror());
		return -EIO;
	}
	o->rows += n;
	if (!o->mip || o->lv.size() < 2)
		return 0;
	for (int y = 0; y < n; y++) {
		if (!convert_pixel_values(o->td, p + (size_t)y * row, TypeFloat, o->f0.data(),
					  o->width * o->nch)) {
			oiio_err(err, "%s: %s", o->path.c_str(),
				 std::string("pixel conversion failed"));
			return -EIO;
		}
		int rc = push_row(o, 0, o->f0.data(), err);
		if (rc)
			return rc;
	}
	return 0;
}

int tiled_finish_impl(img_tiled_out *o, char *err)
{
	if (o->rows != o->height) {
		err_set(err, "%s: only %d of %d rows were written", o->path.c_str(),
			o->rows, o->height);
		return -EINVAL;
	}
	std::vector<char> band;
	for (size_t k = 1; o->mip && k < o->lv.size(); k++) {
		img_tiled_out::level &L = o->lv[k];
		if (L.band_y0 != L.h || L.band_n) { // cannot happen: the cascade ends each level
			oiio_err(err, "%s: %s", o->path.c_str(),
				 std::string("MIP level incomplete"));
			return -EIO;
		}
		ImageSpec s(L.w, L.h, o->nch, o->td);
		s.tile_width = s.tile_height = o->tile;
		s.attribute("compression", "zip");
		// As make_texture: TIFF takes the levels as appended subimages.
		ImageOutput::OpenMode mode = o->out->supports("mipmap")
						     ? ImageOutput::AppendMIPLevel
						     : ImageOutput::AppendSubimage;
		if (!o->out->open(o->tmp, s, mode)) {
			oiio_err(err, "%s: cannot write: %s", o->path.c_str(), o->out->geterror());
			return -EIO;
		}
		band.resize(L.row_bytes * (size_t)std::min(o->tile, L.h));
		for (int y0 = 0; y0 < L.h; y0 += o->tile) {
			int n = std::min(o->tile, L.h - y0);
			int rc = read_all(o->spool, band.data(), L.row_bytes * (size_t)n,
					  L.off + (off_t)L.row_bytes * y0);
			if (rc) {
				oiio_err(err, "%s: %s", o->path.c_str(),
					 std::string("cannot read the spooled MIP levels: ") +
						 std::strerror(-rc));
				return rc;
			}
			if (!write_band(o, L.w, y0, n, band.data())) {
				oiio_err(err, "%s: cannot write: %s", o->path.c_str(),
					 o->out->geterror());
				return -EIO;
			}
		}
	}
	if (!o->out->close()) {
		oiio_err(err, "%s: cannot write: %s", o->path.c_str(), o->out->geterror());
		return -EIO;
	}
	o->out.reset();
	if (o->spool >= 0)
		close(o->spool);
	o->spool = -1;
	return publish(o->tmp, o->path.c_str(), err);
}

} // namespace

extern "C" int img_tiled_open(struct img_tiled_out **out, const char *path, int width,
			      int height, int channels, enum img_type type, int tile, bool mip,
			      const char *description, char err[256])
{
	*out = nullptr;
	if (width <= 0 || height <= 0 || channels <= 0 || channels > 4 || tile <= 0 || tile % 16) {
		err_set(err, "%s: bad image size %dx%dx%d or tile %d", path, width,
			height, channels, tile);
		return -EINVAL;
	}
	img_tiled_out *o = nullptr;
	try {
		o = new img_tiled_out;
		int rc = tiled_open_impl(o, path, width, height, channels, type, tile, mip,
					 description, err);
		if (rc) {
			tiled_discard(o);
			delete o;
			return rc;
		}
		*out = o;
		return 0;
	} catch (const std::bad_alloc &) {
		oom();
	} catch (const std::exception &e) {
		oiio_err(err, "%s: %s", path, e.what());
		if (o) {
			tiled_discard(o);
			delete o;
		}
		return -EIO;
	}
}

extern "C" void img_tiled_set_nodata(struct img_tiled_out *o, double nodata)
{
	// The cascade holds OIIO's float conversion of the stored values (integers normalised):
	// nodata goes through the same conversion, so it compares equal.
	unsigned char raw[4];
	size_t sz = o->td.size();
	if (o->td == TypeDesc::UINT8) {
		uint8_t v = (uint8_t)nodata;
		std::memcpy(raw, &v, 1);
	} else if (o->td == TypeDesc::UINT16) {
		uint16_t v = (uint16_t)nodata;
		std::memcpy(raw, &v, 2);
	} else if (o->td == TypeDesc::INT16) {
		int16_t v = (int16_t)nodata;
		std::memcpy(raw, &v, 2);
	} else {
		float v = (float)nodata;
		std::memcpy(raw, &v, 4);
	}
	float f = 0;
	if (sz > sizeof raw || !convert_pixel_values(o->td, raw, TypeFloat, &f, 1))
		return;
	o->has_nd = true;
	o->nd = f;
}

extern "C" int img_tiled_rows(struct img_tiled_out *o, const void *rows, int n, char err[256])
{
	if (o->failed) {
		err_set(err, "%s: an earlier write failed", o->path.c_str());
		return -EIO;
	}
	try {
		int rc = tiled_rows_impl(o, rows, n, err);
		if (rc && rc != -EINVAL)
			o->failed = true;
		return rc;
	} catch (const std::bad_alloc &) {
		oom();
	} catch (const std::exception &e) {
		oiio_err(err, "%s: %s", o->path.c_str(), e.what());
		o->failed = true;
		return -EIO;
	}
}

extern "C" int img_tiled_finish(struct img_tiled_out *o, char err[256])
{
	int rc;
	try {
		rc = o->failed ? -EIO : tiled_finish_impl(o, err);
		if (o->failed && err)
			err_set(err, "%s: an earlier write failed", o->path.c_str());
	} catch (const std::bad_alloc &) {
		oom();
	} catch (const std::exception &e) {
		oiio_err(err, "%s: %s", o->path.c_str(), e.what());
		rc = -EIO;
	}
	if (rc)
		tiled_discard(o);
	delete o;
	return rc;
}

extern "C" void img_tiled_abort(struct img_tiled_out *o)
{
	if (!o)
		return;
	try {
		tiled_discard(o);
	} catch (...) {
	}
	delete o;
}

namespace {

// Reads the tile (tiled files) or scanline holding pixel (x, y) of the current level of in.
bool read_at(ImageInput *in, const ImageSpec &s, int x, int y, std::vector<char> &buf)
{
	size_t px = (size_t)s.nchannels * s.format.size();
	if (s.tile_width > 0) {
		int tx = s.x + (x - s.x) / s.tile_width * s.tile_width;
		int ty = s.y + (y - s.y) / s.tile_height * s.tile_height;
		buf.resize((size_t)s.tile_width * (size_t)s.tile_height *
			   (size_t)std::max(s.tile_depth, 1) * px);
		return in->read_tile(tx, ty, s.z, s.format, buf.data());
	}
	buf.resize((size_t)s.width * px);
	return in->read_scanline(y, s.z, s.format, buf.data());
}

int check_impl(const char *path, int *levels, char *err)
{
	ImageSpec config;
	config.attribute("oiio:UnassociatedAlpha", 1);
	std::unique_ptr<ImageInput> in = ImageInput::open(path, &config);
	if (!in) {
		oiio_err(err, "%s: %s", path, OIIO::geterror());
		return missing_or(path, -EIO);
	}
	std::vector<char> buf;
	for (int sub = 0; in->seek_subimage(sub, 0); sub++) {
		for (int m = 0; in->seek_subimage(sub, m); m++) {
			if (sub == 0 && levels)
				*levels = m + 1;
			ImageSpec s = in->spec();
			if (s.width <= 0 || s.height <= 0)
				continue;
			int xl = s.x + s.width - 1, yl = s.y + s.height - 1;
			// The first tile, then the last: files are written in order, so a file cut
			// short loses the end of some level.
			bool first = read_at(in.get(), s, s.x, s.y, buf);
			if (first && read_at(in.get(), s, xl, yl, buf))
				continue;
			if (!first)
				xl = s.x, yl = s.y;
			{
				std::string e = in->geterror();
				char where[128];
				snprintf(where, sizeof where,
					 "truncated or corrupt (subimage %d, MIP level %d, %dx%d, "
					 "cannot read around pixel %d,%d)", sub, m, s.width, s.height,
					 xl, yl);
				std::string msg = std::string(where) + ": " +
						  (e.empty() ? std::string("read failed") : e);
				oiio_err(err, "%s: %s", path, msg);
				return -EIO;
			}
		}
	}
	in->geterror(); // seek_subimage past the end leaves a message: drop it
	return 0;
}

} // namespace

extern "C" int img_check_readable(const char *path, int *levels, char err[256])
{
	if (levels)
		*levels = 0;
	return guarded(path, err, [&] {
		int rc = check_impl(path, levels, err);
		return rc ? rc : img_tiff_check_extents(path, err);
	});
}
