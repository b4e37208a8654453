/* http_tls — the HTTPS endpoint's certificate, replaceable while it runs (SIGHUP). libmicrohttpd
 * asks for it on every handshake through GnuTLS's retrieve callback
 * (MHD_OPTION_HTTPS_CERT_CALLBACK), which carries no user pointer: so the current
 * certificate is process-wide — one HTTPS endpoint per process, which is what clipmapd has.
 * A certificate once handed to a handshake is never freed before http_tls_clear (a handshake
 * may still be using the one a reload replaced); reloads are rare, so that is a few KiB each.
 *
 * Threads: any (a mutex guards the current certificate).
 */
#ifndef CLIPMAP_HTTP_TLS_H
#define CLIPMAP_HTTP_TLS_H

/* Parses the PEM certificate chain and its key (NUL-terminated) and makes them the current
 * ones. Returns 0, or -EINVAL with err saying why (nothing changes then). */
int http_tls_set(const char *cert_pem, const char *key_pem, char err[256]);
/* The callback to give libmicrohttpd (a gnutls_certificate_retrieve_function2 *). */
void *http_tls_callback(void);
/* Frees every certificate set (after the endpoint stopped). */
void http_tls_clear(void);

#endif
