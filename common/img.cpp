// img — the only C++ that touches OpenImageIO; see img.h. Every extern "C" function catches
// everything: OIIO reports most failures by return value, but std::bad_alloc and friends must
// not unwind into C. An img_cache wraps a private OIIO::ImageCache (thread-safe; OIIO keeps
// error messages per thread, so concurrent readers do not see each other's errors).
#include "img.h"

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imagecache.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <memory>
#include <new>
#include <string>
#include <sys/stat.h>
#include <unistd.h>

using namespace OIIO;

struct img_cache {
	ImageCache *ic;
};

namespace {

void set_err(char *err, const char *fmt, const char *a, const std::string &b)
{
	if (!err)
		return;
	// OIIO repeats one failure at several layers, one line each: the first says it best.
	std::string m = b.substr(0, b.find('\n'));
	while (!m.empty() && m.back() == ' ')
		m.pop_back();
	if (m.empty())
		m = "unknown OpenImageIO error";
	snprintf(err, 256, fmt, a, m.c_str());
}

[[noreturn]] void oom()
{
	std::fprintf(stderr, "clipmap: out of memory in OpenImageIO\n");
	std::abort();
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
		if (err)
			snprintf(err, 256, "%s: cannot write a%s image with extension \"%s\" "
				 "(use .png, .tif or .exr)", path, tiled ? " tiled" : "n",
				 e.c_str());
		return -EINVAL;
	}
	if (!ok) {
		if (err)
			snprintf(err, 256, "%s: %s cannot hold %s pixels", path, *fmt,
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
		set_err(err, "%s: %s", path, std::string("cannot publish: ") + std::strerror(-rc));
		unlink(tmp.c_str());
	}
	return rc;
}

int write_impl(const char *path, int width, int height, int channels, enum img_type type,
	       const void *pixels, int tile, bool mip, const char *desc, char *err)
{
	if (width <= 0 || height <= 0 || channels <= 0 || !pixels) {
		if (err)
			snprintf(err, 256, "%s: bad image size %dx%dx%d", path, width, height,
				 channels);
		return -EINVAL;
	}
	const char *fmt = nullptr;
	int rc = pick_format(path, type, tile > 0, &fmt, err);
	if (rc)
		return rc;
	std::string tmp = std::string(path) + ".tmp";
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
			set_err(err, "%s: cannot write: %s", path, OIIO::geterror());
			unlink(tmp.c_str());
			return -EIO;
		}
		return publish(tmp, path, err);
	}
	std::unique_ptr<ImageOutput> out = ImageOutput::create(fmt);
	if (!out) {
		set_err(err, "%s: %s", path, OIIO::geterror());
		return -EIO;
	}
	if (!out->open(tmp, spec) || !out->write_image(to_desc(type), pixels)) {
		set_err(err, "%s: cannot write: %s", path, out->geterror());
		out->close();
		unlink(tmp.c_str());
		return -EIO;
	}
	if (!out->close()) {
		set_err(err, "%s: cannot write: %s", path, out->geterror());
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
		return c;
	} catch (const std::bad_alloc &) {
		oom();
	} catch (...) {
		return nullptr;
	}
}

extern "C" void img_cache_destroy(struct img_cache *c)
{
	if (!c)
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
	try {
		ImageSpec spec;
		ustring name(path);
		if (!c->ic->get_imagespec(name, spec, 0, 0, true)) {
			set_err(err, "%s: %s", path, c->ic->geterror());
			return missing_or(path, -EIO);
		}
		fill_info(spec, out);
		int levels = 1;
		if (c->ic->get_image_info(name, 0, 0, ustring("miplevels"), TypeInt, &levels) &&
		    levels > 0)
			out->mip_levels = levels;
		c->ic->geterror(true);
		return 0;
	} catch (const std::bad_alloc &) {
		oom();
	} catch (const std::exception &e) {
		set_err(err, "%s: %s", path, e.what());
		return -EIO;
	}
}

extern "C" int img_cache_level_size(struct img_cache *c, const char *path, int miplevel,
				    int *width, int *height, char err[256])
{
	try {
		ImageSpec spec;
		if (!c->ic->get_imagespec(ustring(path), spec, 0, miplevel, false)) {
			set_err(err, "%s: %s", path, c->ic->geterror());
			if (miplevel > 0)
				return -EINVAL;
			return missing_or(path, -EIO);
		}
		*width = spec.width;
		*height = spec.height;
		return 0;
	} catch (const std::bad_alloc &) {
		oom();
	} catch (const std::exception &e) {
		set_err(err, "%s: %s", path, e.what());
		return -EIO;
	}
}

extern "C" int img_cache_read(struct img_cache *c, const char *path, int miplevel, int x0, int x1,
			      int y0, int y1, int chbegin, int chend, enum img_type type, void *dst,
			      size_t dst_stride, char err[256])
{
	TypeDesc td = to_desc(type);
	if (x1 <= x0 || y1 <= y0 || chbegin < 0 || chend <= chbegin || td == TypeDesc::UNKNOWN) {
		if (err)
			snprintf(err, 256, "%s: bad region [%d,%d)x[%d,%d) channels [%d,%d)", path,
				 x0, x1, y0, y1, chbegin, chend);
		return -EINVAL;
	}
	try {
		size_t px = img_type_bytes(type) * (size_t)(chend - chbegin);
		size_t row = dst_stride ? dst_stride : px * (size_t)(x1 - x0);
		ustring name(path);
		if (read_from_tiles(c->ic, name, miplevel, x0, x1, y0, y1, chbegin, chend, td,
				    (char *)dst, row))
			return 0;
		stride_t xs = (stride_t)px, ys = (stride_t)row;
		if (!c->ic->get_pixels(name, 0, miplevel, x0, x1, y0, y1, 0, 1, chbegin,
				       chend, td, dst, xs, ys, AutoStride, chbegin, chend)) {
			set_err(err, "%s: %s", path, c->ic->geterror());
			return missing_or(path, -EIO);
		}
		return 0;
	} catch (const std::bad_alloc &) {
		oom();
	} catch (const std::exception &e) {
		set_err(err, "%s: %s", path, e.what());
		return -EIO;
	}
}

extern "C" void img_cache_invalidate(struct img_cache *c, const char *path)
{
	try {
		c->ic->invalidate(ustring(path), true);
	} catch (...) {
	}
}

extern "C" int img_write(const char *path, int width, int height, int channels,
			 enum img_type type, const void *pixels, char err[256])
{
	try {
		return write_impl(path, width, height, channels, type, pixels, 0, false, nullptr, err);
	} catch (const std::bad_alloc &) {
		oom();
	} catch (const std::exception &e) {
		set_err(err, "%s: %s", path, e.what());
		return -EIO;
	}
}

extern "C" int img_write_tiled(const char *path, int width, int height, int channels,
			       enum img_type type, const void *pixels, int tile, bool mip,
			       char err[256])
{
	if (tile <= 0 || tile % 16) {
		if (err)
			snprintf(err, 256, "%s: tile size %d is not a positive multiple of 16",
				 path, tile);
		return -EINVAL;
	}
	try {
		return write_impl(path, width, height, channels, type, pixels, tile, mip, nullptr, err);
	} catch (const std::bad_alloc &) {
		oom();
	} catch (const std::exception &e) {
		set_err(err, "%s: %s", path, e.what());
		return -EIO;
	}
}

extern "C" int img_write_tiled_desc(const char *path, int width, int height, int channels,
				    enum img_type type, const void *pixels, int tile, bool mip,
				    const char *description, char err[256])
{
	if (tile <= 0 || tile % 16) {
		if (err)
			snprintf(err, 256, "%s: tile size %d is not a positive multiple of 16",
				 path, tile);
		return -EINVAL;
	}
	try {
		return write_impl(path, width, height, channels, type, pixels, tile, mip,
				  description, err);
	} catch (const std::bad_alloc &) {
		oom();
	} catch (const std::exception &e) {
		set_err(err, "%s: %s", path, e.what());
		return -EIO;
	}
}

extern "C" int img_cache_description(struct img_cache *c, const char *path, char *buf, size_t n,
				     char err[256])
{
	if (n)
		buf[0] = 0;
	try {
		ImageSpec spec;
		if (!c->ic->get_imagespec(ustring(path), spec, 0, 0, false)) {
			set_err(err, "%s: %s", path, c->ic->geterror());
			return missing_or(path, -EIO);
		}
		std::string d = spec.get_string_attribute("ImageDescription");
		if (d.empty())
			return -ENODATA;
		if (n)
			snprintf(buf, n, "%s", d.c_str());
		return 0;
	} catch (const std::bad_alloc &) {
		oom();
	} catch (const std::exception &e) {
		set_err(err, "%s: %s", path, e.what());
		return -EIO;
	}
}

extern "C" int img_read(const char *path, enum img_type type, void **pixels,
			struct img_info *info, char err[256])
{
	*pixels = nullptr;
	try {
		ImageSpec config;
		config.attribute("oiio:UnassociatedAlpha", 1);
		std::unique_ptr<ImageInput> in = ImageInput::open(path, &config);
		if (!in) {
			set_err(err, "%s: %s", path, OIIO::geterror());
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
			set_err(err, "%s: %s", path, in->geterror());
			std::free(buf);
			return -EIO;
		}
		in->close();
		if (info)
			*info = inf;
		*pixels = buf;
		return 0;
	} catch (const std::bad_alloc &) {
		oom();
	} catch (const std::exception &e) {
		set_err(err, "%s: %s", path, e.what());
		return -EIO;
	}
}
