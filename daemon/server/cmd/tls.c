/*
 * tls.c -- TLS on the protocol's TCP listeners, with OpenSSL: the
 * server's context (certificate, key, TLS 1.2 at least), and the
 * non-blocking handshake, reads, writes and close of one socket.
 *
 * Which listeners speak TLS is the tls key (config.h): by default those
 * beyond loopback, where tokens would otherwise travel in clear text; a
 * daemon told to listen there without a certificate refuses to start.
 * The context is made at start and again on SIGHUP (a renewed
 * certificate); connections keep the one they were accepted with.
 *
 * Every call here is non-blocking.  The functions return what read(2) and
 * write(2) would, with errno EAGAIN when OpenSSL wants the socket again
 * (in either direction: the event loop watches reads on every open
 * connection), so that conn.c treats a TLS connection as it treats a
 * plain one.  OpenSSL may hold decrypted bytes the socket no longer
 * signals (SSL_pending): conn.c reads them before it sleeps.
 */
#include <errno.h>
#include <openssl/err.h>
#include <openssl/ssl.h>
#include <stdio.h>
#include <string.h>

#include "cmd.h"
#include "log.h"

/* The first queued OpenSSL error as text ("" when none), queue cleared. */
static void ssl_error_text(char *buf, size_t len)
{
	unsigned long e = ERR_get_error();
	buf[0] = '\0';
	if (e)
		ERR_error_string_n(e, buf, len);
	ERR_clear_error();
}

int cmd_tls_load(cmd_server *d, const srv_config *cfg, char *msg, size_t msglen)
{
	if (!cfg->tls_cert_file[0] && !cfg->tls_key_file[0]) {
		SSL_CTX_free(d->tls_ctx);
		d->tls_ctx = NULL;
		return 0;
	}
	if (!cfg->tls_cert_file[0] || !cfg->tls_key_file[0]) {
		snprintf(msg, msglen,
		         "TLS needs both tls_cert_file and tls_key_file");
		return -1;
	}
	char why[256];
	SSL_CTX *ctx = SSL_CTX_new(TLS_server_method());
	if (!ctx || !SSL_CTX_set_min_proto_version(ctx, TLS1_2_VERSION)) {
		ssl_error_text(why, sizeof(why));
		snprintf(msg, msglen, "TLS: cannot make a context: %s", why);
		SSL_CTX_free(ctx);
		return -1;
	}
	const char *bad = NULL;
	if (SSL_CTX_use_certificate_chain_file(ctx, cfg->tls_cert_file) != 1)
		bad = cfg->tls_cert_file;
	else if (SSL_CTX_use_PrivateKey_file(ctx, cfg->tls_key_file,
	                                     SSL_FILETYPE_PEM) != 1 ||
	         SSL_CTX_check_private_key(ctx) != 1)
		bad = cfg->tls_key_file;
	if (bad) {
		ssl_error_text(why, sizeof(why));
		snprintf(msg, msglen, "TLS: '%s': %s", bad, why);
		SSL_CTX_free(ctx);
		return -1;
	}
	SSL_CTX_set_mode(ctx, SSL_MODE_ENABLE_PARTIAL_WRITE |
	                              SSL_MODE_ACCEPT_MOVING_WRITE_BUFFER);
	SSL_CTX_set_options(ctx, SSL_OP_NO_RENEGOTIATION);
	SSL_CTX_free(d->tls_ctx);
	d->tls_ctx = ctx;
	return 0;
}

void cmd_tls_free(cmd_server *d)
{
	SSL_CTX_free(d->tls_ctx);
	d->tls_ctx = NULL;
}

SSL *cmd_tls_new(cmd_server *d, int fd)
{
	SSL *ssl = d->tls_ctx ? SSL_new(d->tls_ctx) : NULL;
	if (ssl && SSL_set_fd(ssl, fd) != 1) {
		SSL_free(ssl);
		ssl = NULL;
	}
	if (ssl)
		SSL_set_accept_state(ssl);
	return ssl;
}

/* Map an OpenSSL result to read/write's: EAGAIN to be called again,
 * 0 for the peer's close_notify, -1 with errno for a failure. */
static int result(SSL *ssl, int r, char *why, size_t len)
{
	int e = SSL_get_error(ssl, r);
	if (e == SSL_ERROR_WANT_READ || e == SSL_ERROR_WANT_WRITE) {
		errno = EAGAIN;
		return -1;
	}
	if (e == SSL_ERROR_ZERO_RETURN)
		return 0;
	if (why)
		ssl_error_text(why, len);
	else
		ERR_clear_error();
	if (e == SSL_ERROR_SYSCALL && errno == 0)
		return 0; /* EOF without close_notify */
	if (e != SSL_ERROR_SYSCALL)
		errno = EPROTO;
	return -1;
}

int cmd_tls_handshake(SSL *ssl, char *why, size_t len)
{
	int r = SSL_do_handshake(ssl);
	if (r == 1)
		return 1;
	int rc = result(ssl, r, why, len);
	if (rc == 0) {
		snprintf(why, len, "closed during the TLS handshake");
		return -1;
	}
	return errno == EAGAIN ? 0 : -1;
}

ssize_t cmd_tls_read(SSL *ssl, void *buf, size_t len)
{
	size_t got = 0;
	int r = SSL_read_ex(ssl, buf, len, &got);
	if (r == 1)
		return (ssize_t)got;
	return result(ssl, r, NULL, 0);
}

ssize_t cmd_tls_write(SSL *ssl, const void *buf, size_t len)
{
	size_t put = 0;
	int r = SSL_write_ex(ssl, buf, len, &put);
	if (r == 1)
		return (ssize_t)put;
	int rc = result(ssl, r, NULL, 0);
	if (rc == 0)
		errno = EPIPE;
	return -1;
}

int cmd_tls_pending(SSL *ssl)
{
	return ssl && SSL_pending(ssl) > 0;
}

void cmd_tls_close_notify(SSL *ssl)
{
	if (ssl && SSL_is_init_finished(ssl))
		SSL_shutdown(ssl); /* best effort: one try, non-blocking */
	ERR_clear_error();
}
