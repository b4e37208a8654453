/* ctl_prefetch — `clipmapctl prefetch`: starts a PREFETCH job (a bbox or a path corridor over
 * a polygon coverage, over a level range), shows its progress (a redrawn bar on a terminal, a plain line per second
 * otherwise) and a summary, and cancels it when stop_fd becomes readable (the caller turns
 * SIGINT into that, e.g. with a signalfd).
 * No state of its own; the connection has one owner thread.
 */
#ifndef CLIPMAP_CTL_PREFETCH_H
#define CLIPMAP_CTL_PREFETCH_H
#include <stdbool.h>
#include <stdio.h>

#include "client/net.h"

struct ctl_prefetch_opts {
	const char *planet;
	const char *layers;	/* "a,b" layer names; NULL: every layer */
	uint8_t shape;		/* PROTO_SHAPE_BBOX, _PATH or _POLYGON */
	struct geo_rect bbox;
	const struct proto_lonlat *points; /* path or polygon, borrowed */
	uint32_t npoints;
	const uint32_t *rings; /* polygon: points per ring, borrowed */
	uint32_t nrings;
	double width_m;
	uint8_t lmin, lmax;
	bool json; /* --dry-run: the estimate as JSON */
};

struct ctl_prefetch_ui {
	FILE *progress; /* where progress goes (stderr); NULL: none */
	bool tty;	/* redraw one line with a bar instead of a line per second */
	FILE *summary;	/* the summary line (stdout); NULL: none */
	int stop_fd;	/* readable: cancel (the byte is read); < 0: none */
	int stall_ms;	/* no message for this long is an error; 0: 30 s */
	int cancel_wait_ms; /* how long to wait for the cancel to be acknowledged; 0: 3 s */
	int timeout_ms;	/* for the OPEN reply; 0: NET_DEFAULT_TIMEOUT_MS */
};

/* Runs the job to its end. Returns 0 (done), -ECANCELED (stopped through stop_fd, after the
 * daemon acknowledged or cancel_wait_ms passed), -EIO (the job failed or was cancelled by the
 * daemon) or another -errno, with err filled. *final (may be NULL) gets the last progress. */
int ctl_prefetch_run(struct net_conn *c, const struct ctl_prefetch_opts *o,
		     const struct ctl_prefetch_ui *ui, struct proto_prefetch_progress *final,
		     char err[256]);

/* `prefetch --dry-run`: asks the daemon for the job's estimate (PREFETCH_DRY) and prints the
 * tile count and bytes per level, the tier the tiles would go to with its budget, and whether
 * the job would run (text, or JSON with o->json) to out. Returns 0, or -errno with err. */
int ctl_prefetch_dry(struct net_conn *c, const struct ctl_prefetch_opts *o, int timeout_ms,
		     FILE *out, char err[256]);

#endif
