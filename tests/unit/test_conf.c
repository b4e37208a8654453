/* test_conf — clipmapd.conf parsing: defaults, every key of the shipped file, relative paths,
 * and the errors a user gets (file:line: key: message) for bad values, unknown keys and
 * sections, and a non-loopback listener without a token. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <string.h>

#include "daemon/conf.h"
#include "engine/planet.h"

static void parse_fails(const char *text, const char *expect)
{
	struct conf c;
	char err[256] = "";
	int rc = conf_parse("/etc/x/d.conf", text, strlen(text), &c, err);
	if (rc == 0 || !strstr(err, expect))
		fail_msg("expected error containing \"%s\", got rc=%d \"%s\"", expect, rc, err);
}

static void test_defaults(void **state)
{
	(void)state;
	struct conf c;
	char err[256];
	assert_int_equal(conf_parse("/etc/x/d.conf", "", 0, &c, err), 0);
	assert_string_equal(c.unix_path, "/run/clipmapd/clipmapd.sock");
	assert_int_equal(c.ntcp, 1);
	assert_string_equal(c.tcp[0], "127.0.0.1:7878");
	assert_null(c.token_file);
	assert_int_equal(c.cache_bytes, (size_t)1024 << 20);
	/* The daemon's image cache is as large as the one a tool's planet makes by itself. */
	assert_int_equal(c.image_cache_mb, PLANET_IMAGE_CACHE_MB);
	assert_int_equal(c.image_cache_mb, 256);
	assert_int_equal(c.max_want, 4096);
	assert_int_equal(c.log_level, LOG_INFO);
	conf_fini(&c);
}

static void test_shipped_file(void **state)
{
	(void)state;
	struct conf c;
	char err[256] = "";
	int rc = conf_load("conf/clipmapd.conf", &c, err);
	if (rc)
		fail_msg("%s", err);
	assert_string_equal(c.planets_dir, "/etc/clipmap/planets");
	assert_int_equal(c.max_pending, (uint64_t)8192 << 10);
	assert_int_equal(c.send_queue_ms, 100);
	assert_true(c.bbr);
	assert_int_equal(c.raw_above_mbit, 800);
	assert_int_equal(c.image_cache_mb, 256);
	/* [engine] cache_mb and [http] cache_mb are two caches: the file sets both (the second
	 * once set the first, so every daemon run from this file had a 64 MiB tile cache) */
	assert_int_equal(c.cache_bytes, (size_t)1024 << 20);
	assert_int_equal(c.http_cache_mb, 64);
	assert_null(c.store_path); /* no disk tier unless a path is set */
	assert_int_equal(c.store_bytes, (uint64_t)1024 << 20);
	assert_int_equal(c.disk_codec, CONF_DISK_ZSTD); /* what issue 13 asked: zstd at rest */
	conf_fini(&c);
}

static void test_values(void **state)
{
	(void)state;
	const char *t = "[listen]\nunix =\ntcp = 127.0.0.1:0, [::1]:9000, 10.0.0.1:7878\n"
			"token_file = secret\nrequire_token = tcp\nunix_mode = 0600\n"
			"[engine]\nplanets = p\nworkers = 3\ncache_mb = 64\nimage_cache_mb = 48\n"
			"[session]\nmax_pending_kb = 128\nmax_rate = 0\ncompress = never\n"
			"send_queue_ms = 0\nbbr = no\nraw_above_mbit = 0\n"
			"[log]\nlevel = debug\n[store]\npath = tiles.lmdb\ndisk_mb = 512\ndisk_codec = lz4\n"
			"[http]\ncache_mb = 32\n";
	struct conf c;
	char err[256] = "";
	int rc = conf_parse("/etc/x/d.conf", t, strlen(t), &c, err);
	if (rc)
		fail_msg("%s", err);
	assert_null(c.unix_path);
	assert_int_equal(c.ntcp, 3);
	assert_string_equal(c.tcp[1], "[::1]:9000");
	assert_string_equal(c.token_file, "/etc/x/secret");
	assert_string_equal(c.planets_dir, "/etc/x/p");
	assert_int_equal(c.require_token, CONF_TOKEN_TCP);
	assert_int_equal(c.unix_mode, 0600);
	assert_int_equal(c.workers, 3);
	assert_int_equal(c.cache_bytes, (size_t)64 << 20); /* not [http]'s */
	assert_int_equal(c.http_cache_mb, 32);
	assert_int_equal(c.image_cache_mb, 48);
	assert_int_equal(c.max_pending, 128u << 10);
	assert_int_equal(c.compress, CONF_COMPRESS_NEVER);
	assert_int_equal(c.send_queue_ms, 0);
	assert_false(c.bbr);
	assert_int_equal(c.raw_above_mbit, 0);
	assert_int_equal(c.log_level, LOG_DEBUG);
	assert_string_equal(c.store_path, "/etc/x/tiles.lmdb");
	assert_int_equal(c.store_bytes, (uint64_t)512 << 20);
	assert_int_equal(c.disk_codec, CONF_DISK_LZ4);
	conf_fini(&c);
}

/* [store] redis: a Unix socket relative to the file, or host:port; the lease's default. */
static void test_redis(void **state)
{
	(void)state;
	struct conf c;
	char err[256];
	const char *t = "[store]\nredis = unix:run/redis.sock\nredis_password = s3cret\n";
	assert_int_equal(conf_parse("/etc/x/d.conf", t, strlen(t), &c, err), 0);
	assert_string_equal(c.store_redis, "unix:/etc/x/run/redis.sock");
	assert_string_equal(c.store_redis_password, "s3cret");
	assert_int_equal(c.store_redis_lease_ms, 2000);
	conf_fini(&c);
	t = "[store]\nredis = 10.0.0.5:6379\nredis_lease_ms = 500\n";
	assert_int_equal(conf_parse("/etc/x/d.conf", t, strlen(t), &c, err), 0);
	assert_string_equal(c.store_redis, "10.0.0.5:6379");
	assert_null(c.store_redis_password);
	assert_int_equal(c.store_redis_lease_ms, 500);
	conf_fini(&c);
	assert_int_equal(conf_parse("/etc/x/d.conf", "", 0, &c, err), 0);
	assert_null(c.store_redis); /* no shared tier unless set */
	conf_fini(&c);
}

static void test_errors(void **state)
{
	(void)state;
	parse_fails("[listen]\nport = 1\n", "/etc/x/d.conf:2: port: unknown key in [listen]");
	parse_fails("[server]\n", "/etc/x/d.conf:1: unknown section [server]");
	parse_fails("[engine]\nworkers = lots\n", "d.conf:2: workers: \"lots\": expected an integer");
	parse_fails("[engine]\ncache_mb = 1\n", "d.conf:2: cache_mb:");
	parse_fails("[store]\ndisk_mb = 0\n", "d.conf:2: disk_mb: \"0\": expected an integer in [1, ");
	parse_fails("[store]\nsize = 1\n", "d.conf:2: size: unknown key in [store]");
	parse_fails("[store]\ndisk_codec = gzip\n",
		    "d.conf:2: disk_codec: \"gzip\": expected zstd or lz4");
	parse_fails("[session]\ncompress = yes\n",
		    "d.conf:2: compress: \"yes\": expected auto, never or always");
	parse_fails("[store]\nredis = localhost\n",
		    "d.conf:2: redis: \"localhost\" is not unix:/path or host:port");
	parse_fails("[store]\nredis = unix:\n", "d.conf:2: redis: unix: needs a socket path");
	parse_fails("[store]\nredis_lease_ms = 10\n",
		    "d.conf:2: redis_lease_ms: \"10\": expected an integer in [50, 600000]");
	parse_fails("[session]\nsend_queue_ms = -5\n",
		    "d.conf:2: send_queue_ms: \"-5\": expected an integer in [0, 10000]");
	parse_fails("[session]\nbbr = maybe\n", "d.conf:2: bbr: \"maybe\": expected true or false");
	parse_fails("[engine]\nimage_cache_mb = 8\n",
		    "d.conf:2: image_cache_mb: \"8\": expected an integer in [16, 1048576]");
	parse_fails("\n[engine]\nimage_cache_mb = 1G\n", "d.conf:3: image_cache_mb: \"1G\"");
	parse_fails("[engine]\nimage_cache_mb = -256\n", "d.conf:2: image_cache_mb:");
	parse_fails("[engine]\nimage_cache_mb = 2000000\n", "d.conf:2: image_cache_mb:");
	parse_fails("[session]\nimage_cache_mb = 64\n",
		    "d.conf:2: image_cache_mb: unknown key in [session]");
	parse_fails("\n[listen]\ntcp = localhost\n", "d.conf:3: tcp: \"localhost\" is not host:port");
	parse_fails("[listen]\ntcp = 1.2.3.4:99999\n", "is not host:port");
	parse_fails("[listen]\ntcp = 0.0.0.0:7878\n",
		    "d.conf:2: tcp: listener 0.0.0.0:7878 requires a token: set token_file");
	parse_fails("[listen]\nrequire_token = tcp\n", "requires a token");
	parse_fails("[listen]\nrequire_token = maybe\n", "d.conf:2: require_token: \"maybe\"");
	parse_fails("[log]\nlevel = loud\n", "d.conf:2: level:");
	parse_fails("[listen]\nunix =\ntcp =\n", "no listener");
	parse_fails("[session]\nmax_want = 5000\n", "max_want");
	parse_fails("[session]\nmax_frame_kb = 8\n", "d.conf:2: max_frame_kb:");
	parse_fails("[listen]\nunix_mode = rw\n", "unix_mode");
	/* a key given twice, in one section or in two of the same name */
	parse_fails("[engine]\nworkers = 1\nworkers = 2\n",
		    "d.conf:3: workers: given twice in [engine] (first at line 2)");
	parse_fails("[engine]\nworkers = 1\n[log]\nlevel = info\n[engine]\nworkers = 2\n",
		    "d.conf:6: workers: given twice in [engine] (first at line 2)");
	parse_fails("[engine]\nstrict_planets = maybe\n",
		    "d.conf:2: strict_planets: \"maybe\": expected true or false");
	struct conf c;
	char err[256] = "";
	const char *strict = "[engine]\nstrict_planets = true\n";
	assert_int_equal(conf_parse("/etc/x/d.conf", strict, strlen(strict), &c, err), 0);
	assert_true(c.strict_planets);
	conf_fini(&c);
	assert_true(conf_load("/nonexistent/clipmapd.conf", &c, err) < 0);
	assert_non_null(strstr(err, "/nonexistent/clipmapd.conf"));
}

static void test_loopback(void **state)
{
	(void)state;
	assert_true(conf_addr_is_loopback("127.0.0.1:1"));
	assert_true(conf_addr_is_loopback("127.9.9.9:1"));
	assert_true(conf_addr_is_loopback("[::1]:1"));
	assert_true(conf_addr_is_loopback("localhost:1"));
	assert_false(conf_addr_is_loopback("0.0.0.0:1"));
	assert_false(conf_addr_is_loopback("[::]:1"));
	assert_false(conf_addr_is_loopback("192.168.1.1:1"));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_defaults), cmocka_unit_test(test_shipped_file),
		cmocka_unit_test(test_values),	 cmocka_unit_test(test_errors),
		cmocka_unit_test(test_loopback),	 cmocka_unit_test(test_redis),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
