/* gl_context — an offscreen OpenGL 3.3+ core context and the table of GL entry points the
 * client calls through (struct gl). EGL surfaceless first (Mesa llvmpipe works without a GPU
 * or a display), OSMesa (dlopen'ed libOSMesa.so.8) as the fallback; every GL function is
 * resolved through the context's own GetProcAddress so the two never mix.
 *
 * Thread-safety: a context is current on the thread that created it; use it there only.
 * Ownership: gl_context_create returns an owned context; gl_context_destroy frees it.
 */
#ifndef CLIPMAP_GL_CONTEXT_H
#define CLIPMAP_GL_CONTEXT_H
#include <GL/glcorearb.h>

/* X(type, name): every GL function the client uses. */
#define GL_FUNCS(X)                                                                            \
	X(PFNGLGETSTRINGPROC, GetString)                                                       \
	X(PFNGLGETERRORPROC, GetError)                                                         \
	X(PFNGLGETINTEGERVPROC, GetIntegerv)                                                   \
	X(PFNGLENABLEPROC, Enable)                                                             \
	X(PFNGLDISABLEPROC, Disable)                                                           \
	X(PFNGLCLEARPROC, Clear)                                                               \
	X(PFNGLCLEARCOLORPROC, ClearColor)                                                     \
	X(PFNGLCLEARDEPTHPROC, ClearDepth)                                                     \
	X(PFNGLDEPTHFUNCPROC, DepthFunc)                                                       \
	X(PFNGLDEPTHMASKPROC, DepthMask)                                                       \
	X(PFNGLVIEWPORTPROC, Viewport)                                                         \
	X(PFNGLFINISHPROC, Finish)                                                             \
	X(PFNGLREADPIXELSPROC, ReadPixels)                                                     \
	X(PFNGLPIXELSTOREIPROC, PixelStorei)                                                   \
	X(PFNGLGENTEXTURESPROC, GenTextures)                                                   \
	X(PFNGLDELETETEXTURESPROC, DeleteTextures)                                             \
	X(PFNGLBINDTEXTUREPROC, BindTexture)                                                   \
	X(PFNGLACTIVETEXTUREPROC, ActiveTexture)                                               \
	X(PFNGLTEXPARAMETERIPROC, TexParameteri)                                               \
	X(PFNGLTEXIMAGE2DPROC, TexImage2D)                                                     \
	X(PFNGLTEXIMAGE3DPROC, TexImage3D)                                                     \
	X(PFNGLTEXSUBIMAGE3DPROC, TexSubImage3D)                                               \
	X(PFNGLGETTEXIMAGEPROC, GetTexImage)                                                   \
	X(PFNGLGENFRAMEBUFFERSPROC, GenFramebuffers)                                           \
	X(PFNGLDELETEFRAMEBUFFERSPROC, DeleteFramebuffers)                                     \
	X(PFNGLBINDFRAMEBUFFERPROC, BindFramebuffer)                                           \
	X(PFNGLFRAMEBUFFERTEXTURE2DPROC, FramebufferTexture2D)                                 \
	X(PFNGLCHECKFRAMEBUFFERSTATUSPROC, CheckFramebufferStatus)                             \
	X(PFNGLBLITFRAMEBUFFERPROC, BlitFramebuffer)                                           \
	X(PFNGLCREATESHADERPROC, CreateShader)                                                 \
	X(PFNGLDELETESHADERPROC, DeleteShader)                                                 \
	X(PFNGLSHADERSOURCEPROC, ShaderSource)                                                 \
	X(PFNGLCOMPILESHADERPROC, CompileShader)                                               \
	X(PFNGLGETSHADERIVPROC, GetShaderiv)                                                   \
	X(PFNGLGETSHADERINFOLOGPROC, GetShaderInfoLog)                                         \
	X(PFNGLCREATEPROGRAMPROC, CreateProgram)                                               \
	X(PFNGLDELETEPROGRAMPROC, DeleteProgram)                                               \
	X(PFNGLATTACHSHADERPROC, AttachShader)                                                 \
	X(PFNGLLINKPROGRAMPROC, LinkProgram)                                                   \
	X(PFNGLGETPROGRAMIVPROC, GetProgramiv)                                                 \
	X(PFNGLGETPROGRAMINFOLOGPROC, GetProgramInfoLog)                                       \
	X(PFNGLUSEPROGRAMPROC, UseProgram)                                                     \
	X(PFNGLGETUNIFORMLOCATIONPROC, GetUniformLocation)                                     \
	X(PFNGLUNIFORM1IPROC, Uniform1i)                                                       \
	X(PFNGLUNIFORM1FPROC, Uniform1f)                                                       \
	X(PFNGLUNIFORM2FPROC, Uniform2f)                                                       \
	X(PFNGLUNIFORM3FPROC, Uniform3f)                                                       \
	X(PFNGLUNIFORM4FPROC, Uniform4f)                                                       \
	X(PFNGLUNIFORM4FVPROC, Uniform4fv)                                                     \
	X(PFNGLUNIFORMMATRIX3FVPROC, UniformMatrix3fv)                                         \
	X(PFNGLUNIFORMMATRIX4FVPROC, UniformMatrix4fv)                                         \
	X(PFNGLGENBUFFERSPROC, GenBuffers)                                                     \
	X(PFNGLDELETEBUFFERSPROC, DeleteBuffers)                                               \
	X(PFNGLBINDBUFFERPROC, BindBuffer)                                                     \
	X(PFNGLBUFFERDATAPROC, BufferData)                                                     \
	X(PFNGLGENVERTEXARRAYSPROC, GenVertexArrays)                                           \
	X(PFNGLDELETEVERTEXARRAYSPROC, DeleteVertexArrays)                                     \
	X(PFNGLBINDVERTEXARRAYPROC, BindVertexArray)                                           \
	X(PFNGLVERTEXATTRIBPOINTERPROC, VertexAttribPointer)                                   \
	X(PFNGLENABLEVERTEXATTRIBARRAYPROC, EnableVertexAttribArray)                           \
	X(PFNGLDRAWELEMENTSPROC, DrawElements)                                                 \
	X(PFNGLDRAWARRAYSPROC, DrawArrays)

#define GL_FUNC_MEMBER(type, name) type name;
struct gl {
	GL_FUNCS(GL_FUNC_MEMBER)
	PFNGLCLIPCONTROLPROC ClipControl; /* NULL below GL 4.5 (then no reversed depth) */
	int major, minor;
};
#undef GL_FUNC_MEMBER

enum gl_backend {
	GL_BACKEND_AUTO = 0, /* EGL surfaceless, else OSMesa */
	GL_BACKEND_EGL,
	GL_BACKEND_OSMESA,
};

struct gl_context;

/* Creates a core 3.3+ context current on this thread and loads the function table.
 * Returns 0 or -errno (-ENODEV: no backend could give a context) with err filled. */
int gl_context_create(enum gl_backend b, struct gl_context **out, char err[256]);
void gl_context_destroy(struct gl_context *c);
/* The function table (borrowed from c). */
const struct gl *gl_context_api(const struct gl_context *c);
/* "egl" or "osmesa", and the GL_RENDERER string. */
const char *gl_context_backend(const struct gl_context *c);
const char *gl_context_renderer(const struct gl_context *c);

/* Fills *gl from a GetProcAddress-like function (get(ud, "glName")) of the context current
 * on this thread — for contexts made elsewhere (the window, gl_window.h). Checks that the
 * context is 3.3 or later. Returns 0 or -errno with err filled. */
typedef void (*gl_proc)(void);
int gl_load_table(struct gl *gl, gl_proc (*get)(void *ud, const char *name), void *ud,
		  char err[256]);

#endif
