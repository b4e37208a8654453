/* fault — see fault.h. */
#include "fault.h"

#include <stdarg.h>
#include <stdio.h>
#include <unistd.h>

static engine_fault_fn sink; /* set before threads start (fault.h) */

void engine_fault_sink(engine_fault_fn fn)
{
	sink = fn;
}

void engine_fault(const char *fmt, ...)
{
	char line[512];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(line, sizeof line, fmt, ap);
	va_end(ap);
	if (sink) {
		sink(line);
		return;
	}
	char out[600];
	int n = snprintf(out, sizeof out, "warning: %s\n", line); /* fits: line < 512 */
	if (n > 0 && write(STDERR_FILENO, out, (size_t)n) < 0)
		return; /* nowhere left to say it */
}
