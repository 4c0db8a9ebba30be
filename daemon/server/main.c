/*
 * main.c -- luxradd, the luxrad daemon: startup order and exit codes.
 *
 * Order: configuration (defaults, file, flags); the daemon state (token,
 * signals, event loop, store, data-directory lock); listeners (so a port
 * in use or a forbidden address fails before anything slow); recovery
 * from the store; threads; then luxradd.addr is written and the loop
 * runs until a shutdown completes.
 *
 * `luxradd user-add NAME ROLE` adds a user to the users file instead
 * (user_add below).
 *
 * Exit status: 0 after a clean shutdown (SIGTERM, SIGINT, "shutdown") or
 * --help / --version; 2 for a configuration the daemon refuses (bad
 * flag or file, TCP beyond loopback without a token); 1 for a runtime
 * failure (data directory, port in use, thread creation).
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cmd.h"
#include "log.h"

/*
 * luxradd user-add NAME ROLE [--config FILE | --users-file FILE]: a new
 * user with a new token, appended to the users file (created 0600); the
 * token is printed once, on stdout.  A running daemon reads it on SIGHUP.
 */
static int user_add(int argc, char **argv)
{
	srv_config cfg;
	char msg[2048] = "";
	if (argc < 4 || argv[2][0] == '-' || argv[3][0] == '-') {
		fprintf(stderr, "Usage: luxradd user-add NAME ROLE [--config "
		                "FILE] [--users-file FILE]\n"
		                "ROLE: read, submit or admin.  Prints the new "
		                "token once.\n");
		return 2;
	}
	const char *name = argv[2], *role = argv[3];
	/* The options after NAME ROLE, as the daemon would read them. */
	argv[3] = argv[0];
	srv_config_default(&cfg);
	int rc = srv_config_from_args(&cfg, argc - 3, argv + 3, msg,
	                              sizeof(msg));
	if (rc != 0) {
		fprintf(stderr, "luxradd user-add: %s\n",
		        rc == 1 ? "no user added" : msg);
		return rc == 1 ? 0 : 2;
	}
	if (!cfg.users_file[0]) {
		fprintf(stderr, "luxradd user-add: no users_file is "
		                "configured: give --users-file FILE\n");
		return 2;
	}
	if (cmd_user_add(cfg.users_file, name, role, stdout, msg,
	                 sizeof(msg)) != 0) {
		fprintf(stderr, "luxradd user-add: %s\n", msg);
		return 1;
	}
	return 0;
}

int main(int argc, char **argv)
{
	static cmd_server d; /* large (paths, listeners): not on the stack */
	srv_config cfg;
	char msg[2048] = "";
	int rc;

	if (argc > 1 && strcmp(argv[1], "user-add") == 0)
		return user_add(argc, argv);
	if (argc > 1 && strcmp(argv[1], "solve-worker") == 0)
		return srv_worker_main(argc, argv);
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

	rc = cmd_server_init(&d, &cfg, argc, argv, msg, sizeof(msg));
	if (rc == 0)
		rc = cmd_server_listen(&d, msg, sizeof(msg));
	if (rc == 0 && srv_recover(&d.core, msg, sizeof(msg)) != 0)
		rc = -1;
	if (rc == 0 && cmd_server_start(&d, msg, sizeof(msg)) != 0)
		rc = -1;
	if (rc != 0) {
		srv_error("%s", msg);
		cmd_server_destroy(&d);
		return rc == -2 ? 2 : 1;
	}
	rc = cmd_server_run(&d);
	cmd_server_destroy(&d);
	return rc;
}
