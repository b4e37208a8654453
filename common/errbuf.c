/* errbuf — see errbuf.h. */
#include "errbuf.h"

#include <errno.h>
#include <stdio.h>

void err_set(char *err, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	err_vset(err, fmt, ap);
	va_end(ap);
}

void err_vset(char *err, const char *fmt, va_list ap)
{
	if (err)
		vsnprintf(err, 256, fmt, ap);
}

void err_vset_at(char *err, const char *path, int line, const char *key, const char *fmt,
		 va_list ap)
{
	if (!err)
		return;
	int n = line > 0 ? snprintf(err, 256, "%s:%d: ", path, line)
			 : snprintf(err, 256, "%s: ", path);
	if (n >= 0 && n < 256 && key)
		n += snprintf(err + n, (size_t)(256 - n), "%s: ", key);
	if (n >= 0 && n < 256)
		vsnprintf(err + n, (size_t)(256 - n), fmt, ap);
}

int err_inval(char *err, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	err_vset(err, fmt, ap);
	va_end(ap);
	return -EINVAL;
}
