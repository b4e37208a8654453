/* gl_context — see gl_context.h. EGL is linked (-lEGL); OSMesa is dlopen'ed so that its
 * libGL-compatible exports never shadow glvnd's. No GL function is called by symbol: all go
 * through the table filled from the backend's GetProcAddress.
 */
#include "gl_context.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <dlfcn.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/errbuf.h"
#include "common/xalloc.h"

/* OSMesa's constants and entry points (GL/osmesa.h would pull in GL/gl.h). */
#define OSMESA_FORMAT 0x22
#define OSMESA_RGBA 0x1908
#define OSMESA_DEPTH_BITS 0x30
#define OSMESA_STENCIL_BITS 0x31
#define OSMESA_ACCUM_BITS 0x32
#define OSMESA_PROFILE 0x33
#define OSMESA_CORE_PROFILE 0x34
#define OSMESA_CONTEXT_MAJOR_VERSION 0x36
#define OSMESA_CONTEXT_MINOR_VERSION 0x37
typedef void *osmesa_ctx;
typedef osmesa_ctx (*osmesa_create_fn)(const int *attribs, osmesa_ctx share);
typedef unsigned char (*osmesa_make_current_fn)(osmesa_ctx, void *buf, unsigned type, int w, int h);
typedef void (*osmesa_destroy_fn)(osmesa_ctx);
typedef void (*(*osmesa_proc_fn)(const char *))(void);

struct gl_context {
	struct gl gl;
	enum gl_backend backend;
	EGLDisplay dpy;
	EGLContext ctx;
	void *osmesa_lib;
	osmesa_ctx octx;
	osmesa_destroy_fn odestroy;
	unsigned char obuf[4 * 4 * 4]; /* OSMesa wants a colour buffer; we draw into our FBOs */
};

int gl_load_table(struct gl *gl, gl_proc (*get)(void *ud, const char *name), void *ud,
		  char err[256])
{
	char name[64];
#define GL_FUNC_LOAD(type, fname)                                                             \
	snprintf(name, sizeof name, "gl%s", #fname);                                           \
	gl->fname = (type)get(ud, name);                                                     \
	if (!gl->fname) {                                                                    \
		err_set(err, "GL entry point %s missing", name);                               \
		return -ENOSYS;                                                                \
	}
	GL_FUNCS(GL_FUNC_LOAD)
#undef GL_FUNC_LOAD
	const char *v = (const char *)gl->GetString(GL_VERSION);
	if (!v || sscanf(v, "%d.%d", &gl->major, &gl->minor) != 2) {
		err_set(err, "cannot read GL_VERSION");
		return -ENODEV;
	}
	if (gl->major * 10 + gl->minor < 33) {
		err_set(err, "OpenGL %s: 3.3 core needed", v);
		return -ENODEV;
	}
	gl->ClipControl = NULL;
	if (gl->major * 10 + gl->minor >= 45)
		gl->ClipControl = (PFNGLCLIPCONTROLPROC)get(ud, "glClipControl");
	return 0;
}

static gl_proc egl_get(void *ud, const char *name)
{
	(void)ud;
	return (gl_proc)eglGetProcAddress(name);
}

static int egl_create(struct gl_context *c, char err[256])
{
	PFNEGLGETPLATFORMDISPLAYEXTPROC gpd =
		(PFNEGLGETPLATFORMDISPLAYEXTPROC)eglGetProcAddress("eglGetPlatformDisplayEXT");
	if (!gpd) {
		err_set(err, "EGL: no eglGetPlatformDisplayEXT");
		return -ENODEV;
	}
	c->dpy = gpd(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, NULL);
	EGLint maj, min;
	if (c->dpy == EGL_NO_DISPLAY || !eglInitialize(c->dpy, &maj, &min)) {
		err_set(err, "EGL: no surfaceless display (0x%x)", (unsigned)eglGetError());
		return -ENODEV;
	}
	if (!eglBindAPI(EGL_OPENGL_API)) {
		err_set(err, "EGL: no OpenGL API");
		return -ENODEV;
	}
	static const EGLint cfg_attr[] = { EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_SURFACE_TYPE,
					   0, EGL_NONE };
	EGLConfig cfg = NULL;
	EGLint n = 0;
	/* Surfaceless contexts may be created without a config (EGL_KHR_no_config_context). */
	if (!eglChooseConfig(c->dpy, cfg_attr, &cfg, 1, &n) || n < 1)
		cfg = NULL;
	static const EGLint ctx_attr[] = { EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 3,
					   EGL_CONTEXT_OPENGL_PROFILE_MASK,
					   EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE };
	c->ctx = eglCreateContext(c->dpy, cfg, EGL_NO_CONTEXT, ctx_attr);
	if (c->ctx == EGL_NO_CONTEXT) {
		err_set(err, "EGL: cannot create a 3.3 core context (0x%x)",
			(unsigned)eglGetError());
		return -ENODEV;
	}
	if (!eglMakeCurrent(c->dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, c->ctx)) {
		err_set(err, "EGL: eglMakeCurrent failed (0x%x)", (unsigned)eglGetError());
		return -ENODEV;
	}
	c->backend = GL_BACKEND_EGL;
	return gl_load_table(&c->gl, egl_get, NULL, err);
}

static gl_proc osmesa_get(void *ud, const char *name)
{
	osmesa_proc_fn f = (osmesa_proc_fn)ud;
	return f(name);
}

static int osmesa_create(struct gl_context *c, char err[256])
{
	c->osmesa_lib = dlopen("libOSMesa.so.8", RTLD_NOW | RTLD_LOCAL);
	if (!c->osmesa_lib) {
		err_set(err, "OSMesa: %s", dlerror());
		return -ENODEV;
	}
	osmesa_create_fn create;
	osmesa_make_current_fn make_current;
	osmesa_proc_fn proc;
	*(void **)&create = dlsym(c->osmesa_lib, "OSMesaCreateContextAttribs");
	*(void **)&make_current = dlsym(c->osmesa_lib, "OSMesaMakeCurrent");
	*(void **)&proc = dlsym(c->osmesa_lib, "OSMesaGetProcAddress");
	*(void **)&c->odestroy = dlsym(c->osmesa_lib, "OSMesaDestroyContext");
	if (!create || !make_current || !proc || !c->odestroy) {
		err_set(err, "OSMesa: entry points missing");
		return -ENODEV;
	}
	static const int attr[] = { OSMESA_FORMAT, OSMESA_RGBA, OSMESA_DEPTH_BITS, 24,
				    OSMESA_STENCIL_BITS, 0, OSMESA_ACCUM_BITS, 0, OSMESA_PROFILE,
				    OSMESA_CORE_PROFILE, OSMESA_CONTEXT_MAJOR_VERSION, 3,
				    OSMESA_CONTEXT_MINOR_VERSION, 3, 0 };
	c->octx = create(attr, NULL);
	if (!c->octx) {
		err_set(err, "OSMesa: cannot create a 3.3 core context");
		return -ENODEV;
	}
	if (!make_current(c->octx, c->obuf, GL_UNSIGNED_BYTE, 4, 4)) {
		err_set(err, "OSMesa: OSMesaMakeCurrent failed");
		return -ENODEV;
	}
	c->backend = GL_BACKEND_OSMESA;
	return gl_load_table(&c->gl, osmesa_get, *(void **)&proc, err);
}

static void teardown(struct gl_context *c)
{
	/* No eglTerminate: it would unload Mesa's driver before LSan symbolises its stacks. */
	if (c->dpy != EGL_NO_DISPLAY && c->ctx != EGL_NO_CONTEXT) {
		eglMakeCurrent(c->dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
		eglDestroyContext(c->dpy, c->ctx);
	}
	c->dpy = EGL_NO_DISPLAY;
	c->ctx = EGL_NO_CONTEXT;
	if (c->octx)
		c->odestroy(c->octx);
	c->octx = NULL;
	if (c->osmesa_lib)
		dlclose(c->osmesa_lib);
	c->osmesa_lib = NULL;
}

int gl_context_create(enum gl_backend b, struct gl_context **out, char err[256])
{
	struct gl_context *c = xcalloc(1, sizeof *c);
	char e1[256] = "";
	int rc = -ENODEV;
	c->dpy = EGL_NO_DISPLAY;
	c->ctx = EGL_NO_CONTEXT;
	if (b == GL_BACKEND_AUTO || b == GL_BACKEND_EGL) {
		rc = egl_create(c, e1);
		if (rc < 0)
			teardown(c);
	}
	if (rc < 0 && (b == GL_BACKEND_AUTO || b == GL_BACKEND_OSMESA)) {
		rc = osmesa_create(c, err);
		if (rc < 0) {
			teardown(c);
			if (e1[0]) {
				char e2[256];
				snprintf(e2, sizeof e2, "%s", err);
				err_set(err, "%.120s; %.120s", e1, e2);
			}
		}
	} else if (rc < 0) {
		err_set(err, "%s", e1);
	}
	if (rc < 0) {
		free(c);
		*out = NULL;
		return rc;
	}
	*out = c;
	return 0;
}

void gl_context_destroy(struct gl_context *c)
{
	if (!c)
		return;
	teardown(c);
	free(c);
}

const struct gl *gl_context_api(const struct gl_context *c) { return &c->gl; }

const char *gl_context_backend(const struct gl_context *c)
{
	return c->backend == GL_BACKEND_OSMESA ? "osmesa" : "egl";
}

const char *gl_context_renderer(const struct gl_context *c)
{
	const char *r = (const char *)c->gl.GetString(GL_RENDERER);
	return r ? r : "?";
}
