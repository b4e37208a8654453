/* http_tls — see http_tls.h. */
#include "http_tls.h"

#include <errno.h>
#include <gnutls/abstract.h>
#include <gnutls/gnutls.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "common/errbuf.h"
#include "common/xalloc.h"

#define MAX_CHAIN 16

struct certset {
	gnutls_pcert_st pcert[MAX_CHAIN];
	unsigned n;
	gnutls_privkey_t key;
	struct certset *older;
};

static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
static struct certset *current; /* the newest; older ones linked behind it */

static void certset_free(struct certset *c)
{
	for (unsigned i = 0; i < c->n; i++)
		gnutls_pcert_deinit(&c->pcert[i]);
	if (c->key)
		gnutls_privkey_deinit(c->key);
	free(c);
}

int http_tls_set(const char *cert_pem, const char *key_pem, char err[256])
{
	struct certset *c = xcalloc(1, sizeof *c);
	gnutls_datum_t cd = { (unsigned char *)(uintptr_t)cert_pem, (unsigned)strlen(cert_pem) },
		       kd = { (unsigned char *)(uintptr_t)key_pem, (unsigned)strlen(key_pem) };
	c->n = MAX_CHAIN;
	int g = gnutls_pcert_list_import_x509_raw(c->pcert, &c->n, &cd, GNUTLS_X509_FMT_PEM, 0);
	if (g < 0 || c->n == 0) {
		c->n = g < 0 ? 0 : c->n;
		err_set(err, "https: certificate: %s", g < 0 ? gnutls_strerror(g) : "none in it");
		certset_free(c);
		return -EINVAL;
	}
	if ((g = gnutls_privkey_init(&c->key)) < 0 ||
	    (g = gnutls_privkey_import_x509_raw(c->key, &kd, GNUTLS_X509_FMT_PEM, NULL, 0)) < 0) {
		err_set(err, "https: key: %s", gnutls_strerror(g));
		certset_free(c);
		return -EINVAL;
	}
	pthread_mutex_lock(&mu);
	c->older = current;
	current = c;
	pthread_mutex_unlock(&mu);
	return 0;
}

static int retrieve(gnutls_session_t s, const gnutls_datum_t *req_ca_dn, int nreqs,
		    const gnutls_pk_algorithm_t *pk_algos, int pk_algos_length,
		    gnutls_pcert_st **pcert, unsigned int *pcert_length, gnutls_privkey_t *privkey)
{
	(void)s, (void)req_ca_dn, (void)nreqs, (void)pk_algos, (void)pk_algos_length;
	pthread_mutex_lock(&mu);
	struct certset *c = current;
	pthread_mutex_unlock(&mu);
	if (!c)
		return -1; /* no certificate: the handshake fails */
	*pcert = c->pcert;
	*pcert_length = c->n;
	*privkey = c->key;
	return 0;
}

void *http_tls_callback(void)
{
	gnutls_certificate_retrieve_function2 *f = retrieve;
	return (void *)f;
}

void http_tls_clear(void)
{
	pthread_mutex_lock(&mu);
	struct certset *c = current;
	current = NULL;
	pthread_mutex_unlock(&mu);
	while (c) {
		struct certset *o = c->older;
		certset_free(c);
		c = o;
	}
}
