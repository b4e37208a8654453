/* gl_window — an on-screen window (GLFW) with an OpenGL 3.3+ core context current on the
 * creating thread, the same function table as gl_context (struct gl, resolved through
 * glfwGetProcAddress), and its input reduced to what the viewer's controls read.
 *
 * Thread-safety: GLFW's rules: create, poll and destroy on the main thread only.
 * Ownership: gl_window_create returns an owned window; gl_window_destroy closes and frees it
 * (GLFW itself stays initialised until the process exits).
 */
#ifndef CLIPMAP_GL_WINDOW_H
#define CLIPMAP_GL_WINDOW_H
#include <stdbool.h>

#include "gl_context.h"

enum gl_window_key {
	GLW_W, GLW_A, GLW_S, GLW_D, GLW_Q, GLW_E,
	GLW_UP, GLW_DOWN, GLW_LEFT, GLW_RIGHT, GLW_PAGE_UP, GLW_PAGE_DOWN,
	GLW_SHIFT,
	GLW_NKEYS
};

/* One poll's worth of input. */
struct gl_window_input {
	double dx, dy;	      /* cursor motion since the last poll, pixels (y down) */
	bool left, right;     /* buttons held (middle counts as right) */
	double wheel;	      /* scroll notches since the last poll, > 0 away from the user */
	bool key[GLW_NKEYS];  /* held */
	bool reset;	      /* R pressed since the last poll */
	int next_layer;	      /* L presses since the last poll (next colour layer) */
	bool quit;	      /* Esc pressed or the window closed */
};

struct gl_window;

/* Opens a width×height window titled `title` (vsync on when the system offers it).
 * Returns 0 or -errno (-ENODEV: no display, or no 3.3 core context) with err filled. */
int gl_window_create(int width, int height, const char *title, struct gl_window **out,
		     char err[256]);
void gl_window_destroy(struct gl_window *w);
const struct gl *gl_window_api(const struct gl_window *w);
/* The drawable's size in pixels (may differ from the window's on HiDPI screens). */
void gl_window_framebuffer_size(struct gl_window *w, int *width, int *height);
/* Processes pending events and fills *in. Never blocks. */
void gl_window_poll(struct gl_window *w, struct gl_window_input *in);
/* Copies framebuffer object fbo (width×height) to the window and shows it. */
void gl_window_present(struct gl_window *w, unsigned fbo, int width, int height);
void gl_window_set_title(struct gl_window *w, const char *title);

#endif
