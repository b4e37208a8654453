/* ctl_prefetch — see ctl_prefetch.h. One poll() loop over the connection and stop_fd; every
 * complete message already buffered is handled before polling again, so a burst of
 * progress messages never waits for the next byte. */
#include "ctl_prefetch.h"

#include <errno.h>
#include <poll.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "common/clock.h"
#include "common/errbuf.h"
#include "ctl_args.h"
#include "ctl_conn.h"

struct run {
	struct net_conn *c;
	const struct ctl_prefetch_ui *ui;
	uint32_t id;
	struct proto_prefetch_progress last;
	bool have, ended;
	double t0, last_print;
	bool line_open; /* a TTY line is drawn and not yet ended */
};

static void show(struct run *r, bool force)
{
	FILE *f = r->ui->progress;
	if (!f || !r->have)
		return;
	double t = clock_now_s();
	char line[256];
	if (r->ui->tty) {
		if (!force && t - r->last_print < 0.1)
			return;
		ctl_fmt_progress(line, sizeof line, r->last.done, r->last.total, r->last.rate, 30);
		fprintf(f, "\r%s\033[K", line);
		r->line_open = true;
	} else {
		if (!force && t - r->last_print < 1.0)
			return;
		ctl_fmt_progress(line, sizeof line, r->last.done, r->last.total, r->last.rate, 0);
		fprintf(f, "prefetch: %s\n", line);
	}
	fflush(f);
	r->last_print = t;
}

static void end_line(struct run *r)
{
	if (r->line_open && r->ui->progress) {
		fputc('\n', r->ui->progress);
		fflush(r->ui->progress);
	}
	r->line_open = false;
}

/* Handles one message. Returns 1 when the job ended, 0 to go on, -errno on failure. */
static int handle(struct run *r, const struct proto_msg *m, char err[256])
{
	if (m->type == PROTO_ERROR) {
		net_error_text(r->c, &m->error, err);
		if (m->error.ref_type == PROTO_PREFETCH && m->error.ref_id == r->id && r->have &&
		    r->last.state == PROTO_JOB_FAILED)
			return -EIO; /* the ERROR that goes with a failed job's PROGRESS */
		return -net_code_errno(m->error.code);
	}
	if (m->type != PROTO_PREFETCH_PROGRESS || m->prefetch_progress.id != r->id)
		return 0; /* tiles or replies of nothing we asked: not ours */
	r->last = m->prefetch_progress;
	r->have = true;
	switch (r->last.state) {
	case PROTO_JOB_RUNNING: show(r, false); return 0;
	case PROTO_JOB_DONE: show(r, true); return 1;
	case PROTO_JOB_CANCELLED:
		show(r, true);
		err_set(err, "%s: the prefetch job was cancelled by the daemon",
			net_peer(r->c));
		return -EIO;
	case PROTO_JOB_FAILED:
		show(r, true);
		err_set(err, "%s: the prefetch job failed after %llu of %llu tiles",
			net_peer(r->c), (unsigned long long)r->last.done,
			(unsigned long long)r->last.total);
		/* an ERROR with the reason should follow; take it if it comes at once */
		{
			struct proto_msg e = { 0 };
			char e2[256];
			if (net_recv(r->c, &e, 500, e2) == 0 && e.type == PROTO_ERROR)
				net_error_text(r->c, &e.error, err);
			proto_msg_fini(&e);
		}
		return -EIO;
	default: return 0;
	}
}

/* After the user asked to stop: PREFETCH_CANCEL, then wait for the acknowledgement. */
static int cancel(struct run *r, char err[256])
{
	struct proto_msg m = { .type = PROTO_PREFETCH_CANCEL, .prefetch_cancel = { .req = r->id } };
	int rc = net_send(r->c, &m, err);
	end_line(r);
	if (rc == 0) {
		int wait = r->ui->cancel_wait_ms ? r->ui->cancel_wait_ms : 3000;
		double deadline = clock_now_s() + wait / 1000.0;
		for (;;) {
			double left = deadline - clock_now_s();
			if (left <= 0)
				break;
			struct proto_msg a = { 0 };
			char e2[256];
			if (net_recv(r->c, &a, (int)(left * 1000) + 1, e2))
				break;
			bool ack = (a.type == PROTO_PREFETCH_PROGRESS && a.prefetch_progress.id == r->id &&
				    a.prefetch_progress.state != PROTO_JOB_RUNNING) ||
				   (a.type == PROTO_ERROR && a.error.ref_id == r->id);
			if (a.type == PROTO_PREFETCH_PROGRESS && a.prefetch_progress.id == r->id) {
				r->last = a.prefetch_progress;
				r->have = true;
			}
			proto_msg_fini(&a);
			if (ack)
				break;
		}
	}
	err_set(err, "prefetch interrupted after %llu of %llu tiles",
		(unsigned long long)r->last.done, (unsigned long long)r->last.total);
	return -ECANCELED;
}

/* Handles every whole message the socket already holds (never blocks). Returns 0, 1 when the
 * job ended, or -errno. */
static int drain(struct net_conn *c, struct run *r, double *last_msg, char err[256])
{
	for (;;) {
		struct proto_msg m = { 0 };
		int g = net_recv(c, &m, 0, err);
		if (g == -EAGAIN)
			return 0;
		if (g)
			return g;
		*last_msg = clock_now_s();
		g = handle(r, &m, err);
		proto_msg_fini(&m);
		if (g)
			return g;
	}
}

/* Opens o's planet and turns --layers into a mask. Returns 0 or -errno with err. */
static int open_layers(struct net_conn *c, const struct ctl_prefetch_opts *o, int timeout_ms,
		       uint64_t *mask, char err[256])
{
	struct proto_msg op = { 0 };
	int rc = net_open_planet(c, o->planet, &op,
				 timeout_ms ? timeout_ms : NET_DEFAULT_TIMEOUT_MS, err);
	if (rc)
		return rc;
	*mask = 0;
	rc = ctl_parse_layers(o->layers, &op.opened.planet, mask, err);
	if (rc == 0 && o->lmax > op.opened.planet.max_level) {
		err_set(err, "--levels %u-%u: planet %.64s has levels 0-%u", o->lmin, o->lmax,
			o->planet, op.opened.planet.max_level);
		rc = -EINVAL;
	}
	proto_msg_fini(&op);
	return rc;
}

static const char *tier_name(uint8_t t)
{
	return t == PROTO_TIER_DISK ? "disk" : t == PROTO_TIER_REMOTE ? "remote" : "memory";
}

int ctl_prefetch_dry(struct net_conn *c, const struct ctl_prefetch_opts *o, int timeout_ms,
		     FILE *out, char err[256])
{
	uint64_t mask;
	int rc = open_layers(c, o, timeout_ms, &mask, err);
	if (rc)
		return rc;
	struct proto_msg q = { .type = PROTO_PREFETCH_DRY,
			       .prefetch_dry = { .id = net_next_req(c), .planet = o->planet,
						 .layers = mask, .shape = o->shape, .lmin = o->lmin,
						 .lmax = o->lmax, .bbox = o->bbox,
						 .width_m = o->width_m, .npoints = o->npoints,
						 .points = o->points, .nrings = o->nrings,
						 .rings = o->rings } };
	if ((rc = net_send(c, &q, err)))
		return rc;
	struct proto_msg r = { 0 };
	rc = net_expect(c, PROTO_PREFETCH_ESTIMATE, &r,
			timeout_ms ? timeout_ms : NET_DEFAULT_TIMEOUT_MS, NULL, NULL, err);
	if (rc)
		return rc;
	const struct proto_prefetch_estimate *e = &r.prefetch_estimate;
	bool over_tiles = e->tiles > e->max_tiles, over_bytes = e->budget && e->bytes > e->budget;
	if (o->json) {
		fprintf(out,
			"{\"planet\": \"%s\", \"tiles\": %llu, \"bytes\": %llu, \"tier\": \"%s\", "
			"\"budget\": %llu, \"used\": %llu, \"max_tiles\": %llu, \"fits\": %s, "
			"\"levels\": [",
			o->planet, (unsigned long long)e->tiles, (unsigned long long)e->bytes,
			tier_name(e->tier), (unsigned long long)e->budget,
			(unsigned long long)e->used, (unsigned long long)e->max_tiles,
			over_tiles || over_bytes ? "false" : "true");
		for (uint8_t i = 0; i < e->nlevels; i++)
			fprintf(out, "%s{\"level\": %u, \"tiles\": %llu, \"bytes\": %llu}",
				i ? ", " : "", e->levels[i].ly, (unsigned long long)e->levels[i].tiles,
				(unsigned long long)e->levels[i].bytes);
		fprintf(out, "]}\n");
	} else {
		char b[32], bud[32], used[32];
		fprintf(out, "%-6s %14s %12s\n", "level", "tiles", "bytes");
		for (uint8_t i = 0; i < e->nlevels; i++) {
			ctl_fmt_bytes(e->levels[i].bytes, b, sizeof b);
			fprintf(out, "%-6u %14llu %12s\n", e->levels[i].ly,
				(unsigned long long)e->levels[i].tiles, b);
		}
		ctl_fmt_bytes(e->bytes, b, sizeof b);
		fprintf(out, "%-6s %14llu %12s\n", "total", (unsigned long long)e->tiles, b);
		ctl_fmt_bytes(e->budget, bud, sizeof bud);
		ctl_fmt_bytes(e->used, used, sizeof used);
		fprintf(out, "%s tier: budget %s, %s held now; the job would take %.1f %% of it\n",
			tier_name(e->tier), bud, used,
			e->budget ? 100.0 * (double)e->bytes / (double)e->budget : 0.0);
		fprintf(out, "this session's limit: %llu tiles per job\n",
			(unsigned long long)e->max_tiles);
		if (over_tiles)
			fprintf(out, "would be refused: more tiles than this session's limit\n");
		else if (over_bytes)
			fprintf(out, "would be refused: larger than the %s tier's budget\n",
				tier_name(e->tier));
		else
			fprintf(out, "would run\n");
	}
	fflush(out);
	proto_msg_fini(&r);
	return 0;
}

int ctl_prefetch_run(struct net_conn *c, const struct ctl_prefetch_opts *o,
		     const struct ctl_prefetch_ui *ui, struct proto_prefetch_progress *final,
		     char err[256])
{
	uint64_t mask;
	int rc = open_layers(c, o, ui->timeout_ms, &mask, err);
	if (rc)
		return rc;

	struct run r = { .c = c, .ui = ui, .id = net_next_req(c), .t0 = clock_now_s() };
	struct proto_msg pf = { .type = PROTO_PREFETCH,
				.prefetch = { .id = r.id, .planet = o->planet, .layers = mask,
					      .shape = o->shape, .lmin = o->lmin, .lmax = o->lmax,
					      .bbox = o->bbox, .width_m = o->width_m,
					      .npoints = o->npoints, .points = o->points,
					      .nrings = o->nrings, .rings = o->rings } };
	rc = net_send(c, &pf, err);
	if (rc)
		return rc;
	int stall = ui->stall_ms ? ui->stall_ms : 30000;
	double last_msg = clock_now_s();
	while (rc == 0) {
		/* everything already buffered first */
		if ((rc = drain(c, &r, &last_msg, err)))
			break;
		struct pollfd p[2] = { { .fd = net_fd(c), .events = POLLIN },
				       { .fd = ui->stop_fd, .events = POLLIN } };
		int np = ui->stop_fd >= 0 ? 2 : 1;
		int left = (int)((last_msg + stall / 1000.0 - clock_now_s()) * 1000);
		if (left <= 0) {
			err_set(err, "%s: no progress from the daemon for %d s", net_peer(c),
				stall / 1000);
			rc = -ETIMEDOUT;
			break;
		}
		int pr = poll(p, (nfds_t)np, left < 1000 ? left : 1000);
		if (pr < 0 && errno != EINTR) {
			rc = -errno;
			err_set(err, "poll: %s", strerror(errno));
			break;
		}
		if (pr > 0 && np == 2 && (p[1].revents & POLLIN)) {
			char buf[128];
			(void)!read(ui->stop_fd, buf, sizeof buf);
			/* what the daemon sent before the interrupt is shown before cancelling */
			if ((rc = drain(c, &r, &last_msg, err)))
				break;
			if (!ui->tty)
				show(&r, true);
			rc = cancel(&r, err);
			break;
		}
		if (!ui->tty)
			show(&r, false);
	}
	if (rc == 1)
		rc = 0;
	end_line(&r);
	if (final)
		*final = r.last;
	if (rc == 0 && ui->summary) {
		double el = clock_now_s() - r.t0;
		char d[32];
		ctl_fmt_duration(el, d, sizeof d);
		fprintf(ui->summary, "prefetch %s: %llu of %llu tiles in %s (%.1f tiles/s)\n",
			o->planet, (unsigned long long)r.last.done, (unsigned long long)r.last.total,
			d, el > 0 ? (double)r.last.done / el : 0.0);
		fflush(ui->summary);
	}
	return rc;
}
