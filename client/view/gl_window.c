/* gl_window — see gl_window.h. GLFW with GLFW_INCLUDE_NONE: GL itself comes only through the
 * struct gl table; vsync is asked for (glfwSwapInterval 1); pacing beyond it is the caller's.
 */
#include "gl_window.h"

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/errbuf.h"
#include "common/xalloc.h"

struct gl_window {
	struct gl gl;
	GLFWwindow *win;
	double cx, cy; /* the cursor at the last poll */
	bool have_cursor;
	double wheel;  /* accumulated by the scroll callback */
	bool reset;    /* R pressed (key callback) */
	int layer;     /* L presses since the last poll (key callback) */
};

static const int key_codes[GLW_NKEYS] = {
	[GLW_W] = GLFW_KEY_W,	      [GLW_A] = GLFW_KEY_A,
	[GLW_S] = GLFW_KEY_S,	      [GLW_D] = GLFW_KEY_D,
	[GLW_Q] = GLFW_KEY_Q,	      [GLW_E] = GLFW_KEY_E,
	[GLW_UP] = GLFW_KEY_UP,	      [GLW_DOWN] = GLFW_KEY_DOWN,
	[GLW_LEFT] = GLFW_KEY_LEFT,   [GLW_RIGHT] = GLFW_KEY_RIGHT,
	[GLW_PAGE_UP] = GLFW_KEY_PAGE_UP, [GLW_PAGE_DOWN] = GLFW_KEY_PAGE_DOWN,
	[GLW_SHIFT] = GLFW_KEY_LEFT_SHIFT,
};

static void glfw_err(const char *what, char err[256])
{
	const char *d = NULL;
	int code = glfwGetError(&d);
	err_set(err, "%s: %s (GLFW 0x%x)", what, d ? d : "unknown error", (unsigned)code);
}

static gl_proc glfw_get(void *ud, const char *name)
{
	(void)ud;
	return (gl_proc)glfwGetProcAddress(name);
}

static void on_scroll(GLFWwindow *win, double xoff, double yoff)
{
	(void)xoff;
	struct gl_window *w = glfwGetWindowUserPointer(win);
	w->wheel += yoff;
}

static void on_key(GLFWwindow *win, int key, int scancode, int action, int mods)
{
	(void)scancode;
	(void)mods;
	struct gl_window *w = glfwGetWindowUserPointer(win);
	if (action != GLFW_PRESS)
		return;
	if (key == GLFW_KEY_ESCAPE)
		glfwSetWindowShouldClose(win, GLFW_TRUE);
	else if (key == GLFW_KEY_R)
		w->reset = true;
	else if (key == GLFW_KEY_L)
		w->layer++;
}

int gl_window_create(int width, int height, const char *title, struct gl_window **out,
		     char err[256])
{
	*out = NULL;
	if (!glfwInit()) {
		glfw_err("no window system", err);
		return -ENODEV;
	}
	glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
	glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
	glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
	glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
	glfwWindowHint(GLFW_DEPTH_BITS, 0); /* the view draws into its own framebuffer */
	struct gl_window *w = xcalloc(1, sizeof *w);
	w->win = glfwCreateWindow(width, height, title, NULL, NULL);
	if (!w->win) {
		glfw_err("cannot open a window with an OpenGL 3.3 core context", err);
		free(w);
		return -ENODEV;
	}
	glfwSetWindowUserPointer(w->win, w);
	glfwMakeContextCurrent(w->win);
	glfwSwapInterval(1);
	glfwSetScrollCallback(w->win, on_scroll);
	glfwSetKeyCallback(w->win, on_key);
	int rc = gl_load_table(&w->gl, glfw_get, NULL, err);
	if (rc < 0) {
		gl_window_destroy(w);
		return rc;
	}
	*out = w;
	return 0;
}

void gl_window_destroy(struct gl_window *w)
{
	if (!w)
		return;
	/* No glfwTerminate: it would unload the GL driver before LSan symbolises its stacks
	 * (as gl_context skips eglTerminate); GLFW stays initialised until exit. */
	if (w->win)
		glfwDestroyWindow(w->win);
	free(w);
}

const struct gl *gl_window_api(const struct gl_window *w) { return &w->gl; }

void gl_window_framebuffer_size(struct gl_window *w, int *width, int *height)
{
	glfwGetFramebufferSize(w->win, width, height);
}

void gl_window_poll(struct gl_window *w, struct gl_window_input *in)
{
	glfwPollEvents();
	memset(in, 0, sizeof *in);
	double x, y;
	glfwGetCursorPos(w->win, &x, &y);
	if (w->have_cursor) {
		in->dx = x - w->cx;
		in->dy = y - w->cy;
	}
	w->cx = x;
	w->cy = y;
	w->have_cursor = true;
	in->left = glfwGetMouseButton(w->win, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS;
	in->right = glfwGetMouseButton(w->win, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS ||
		    glfwGetMouseButton(w->win, GLFW_MOUSE_BUTTON_MIDDLE) == GLFW_PRESS;
	in->wheel = w->wheel;
	w->wheel = 0;
	for (int k = 0; k < GLW_NKEYS; k++)
		in->key[k] = glfwGetKey(w->win, key_codes[k]) == GLFW_PRESS;
	in->key[GLW_SHIFT] |= glfwGetKey(w->win, GLFW_KEY_RIGHT_SHIFT) == GLFW_PRESS;
	in->reset = w->reset;
	w->reset = false;
	in->next_layer = w->layer;
	w->layer = 0;
	in->quit = glfwWindowShouldClose(w->win);
}

void gl_window_present(struct gl_window *w, unsigned fbo, int width, int height)
{
	const struct gl *gl = &w->gl;
	int fw, fh;
	glfwGetFramebufferSize(w->win, &fw, &fh);
	gl->BindFramebuffer(GL_READ_FRAMEBUFFER, fbo);
	gl->BindFramebuffer(GL_DRAW_FRAMEBUFFER, 0);
	gl->BlitFramebuffer(0, 0, width, height, 0, 0, fw, fh, GL_COLOR_BUFFER_BIT,
			    width == fw && height == fh ? GL_NEAREST : GL_LINEAR);
	gl->BindFramebuffer(GL_FRAMEBUFFER, 0);
	glfwSwapBuffers(w->win);
}

void gl_window_set_title(struct gl_window *w, const char *title)
{
	glfwSetWindowTitle(w->win, title);
}
