/*
 * main.c -- luxradd, the luxrad daemon: startup order and exit codes.
 *
 * Order: configuration (defaults, file, flags); the daemon state (token,
 * signals, event loop, store, data-directory lock); listeners (so a port
 * in use or a forbidden address fails before anything slow); recovery
 * from the store; threads; then luxradd.addr is written and the loop
 * runs until a shutdown completes.
 *
 * Exit status: 0 after a clean shutdown (SIGTERM, SIGINT, "shutdown") or
 * --help / --version; 2 for a configuration the daemon refuses (bad
 * flag or file, TCP beyond loopback without a token); 1 for a runtime
 * failure (data directory, port in use, thread creation).
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"
#include "server.h"

int main(int argc, char **argv)
{
	static srv s; /* large (paths, listeners): not on the stack */
	srv_config cfg;
	char msg[2048] = "";
	int rc;

	srv_config_default(&cfg);
	rc = srv_config_from_args(&cfg, argc, argv, msg, sizeof(msg));
	if (rc == 1)
		return 0;
	if (rc != 0) {
		fprintf(stderr, "luxradd: %s\nTry 'luxradd --help'.\n", msg);
		return 2;
	}
	srv_log_set_level(cfg.log_level);
	srv_info("luxradd %s starting (data directory %s)", SRV_VERSION,
	         cfg.data_dir);

	rc = srv_init(&s, &cfg, argc, argv, msg, sizeof(msg));
	if (rc == 0)
		rc = srv_listen(&s, msg, sizeof(msg));
	if (rc == 0 && srv_recover(&s, msg, sizeof(msg)) != 0)
		rc = -1;
	if (rc == 0 && srv_start_threads(&s, msg, sizeof(msg)) != 0)
		rc = -1;
	if (rc != 0) {
		srv_error("%s", msg);
		srv_destroy(&s);
		return rc == -2 ? 2 : 1;
	}
	rc = srv_run(&s);
	srv_destroy(&s);
	return rc;
}
