/*
 * test_daemon_admission.c -- who gets a connection slot, and for how
 * long, on a real luxradd over real sockets (PROTOCOL.md §8, the
 * admission rules at the top of daemon/server/cmd/conn.c):
 *  - a connection refused on accept reads its too_many_connections frame
 *    and then a clean end of stream, not a TCP reset, even when it sent
 *    its hello first;
 *  - connections that never finish their hello, each trickling a byte
 *    now and then so that the idle timeout never fires, cannot lock the
 *    daemon: each is closed by the hello deadline, and a new client gets
 *    in (taking the slot of one that waited a second without hello);
 *  - one address holds at most max_connections_per_address slots;
 *    clients from another address are served meanwhile;
 *  - a request header trickled byte by byte after hello is closed by the
 *    header deadline;
 *  - /metrics counts each refusal by its cause.
 * Other peers are other loopback addresses (127.0.0.2, ...): Linux
 * routes all of 127/8 to the loopback interface.
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "harness.h"

#define REFUSED(cause) "luxradd_connections_refused_total{cause=\"" cause "\"}"

/* Send a hello frame without waiting for its reply. */
static void send_hello(dm_conn *c, const char *client)
{
	json_t *h = json_pack("{s:s, s:i, s:s}", "cmd", "hello", "version", 1,
	                      "client", client);
	dm_send_frame(c, h, NULL, 0);
	json_decref(h);
}

/* The next frame must be an error with this code, then the stream must
 * end cleanly (FIN, not a reset). */
static void expect_refusal(dm_conn *c, const char *code, const char *what)
{
	json_t *f = NULL;
	if (dm_recv(c, DM_REPLY_MS, &f, NULL, NULL) != 1)
		fail_msg("%s: no frame (the connection %s)", what,
		         c->reset ? "was reset" : "closed silently");
	if (strcmp(dm_err_code(f), code) != 0)
		fail_msg("%s: got %s, want the error %s", what, dm_dumps(f),
		         code);
	json_decref(f);
	if (!dm_wait_closed(c, 10000))
		fail_msg("%s: the refused connection stays open", what);
	if (c->reset)
		fail_msg("%s: the frame was followed by a TCP reset, not the "
		         "end of the stream",
		         what);
}

static void test_refused_connections_read_their_frame_then_the_end(void **state)
{
	(void)state;
	const char *args[] = {"--max-connections", "1", NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *holder = dm_open(d, NULL);
	/* A long client name: a hello the daemon has not read when it
	 * closes is what turned the close into a reset. */
	char name[2048];
	memset(name, 'x', sizeof(name) - 1);
	name[sizeof(name) - 1] = '\0';
	for (int i = 0; i < 20; i++) {
		dm_conn *c = dm_connect_tcp(d);
		send_hello(c, name);
		dm_sleep_ms(20); /* the daemon has closed its side by now */
		char what[64];
		snprintf(what, sizeof(what), "refused connection %d", i);
		expect_refusal(c, "too_many_connections", what);
		dm_close(c);
	}
	assert_true(dm_metric(d, REFUSED("max_connections")) == 20);
	json_decref(dm_ok(holder, "{s:s}", "cmd", "status"));
	dm_pass();
}

/*
 * The slowloris: as many connections as the daemon has slots, each from
 * its own address, each sending a hello one byte at a time and never
 * finishing it.  Before the hello deadline they held every slot until
 * the idle timeout, which their bytes kept resetting.
 */
static void test_unfinished_hellos_cannot_lock_the_daemon(void **state)
{
	(void)state;
	enum { SLOTS = 16 };
	const char *args[] = {"--max-connections", "16", "--hello-timeout", "3",
	                      NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *bad[SLOTS];
	for (int i = 0; i < SLOTS; i++) {
		char src[32];
		snprintf(src, sizeof(src), "127.0.0.%d", 10 + i);
		bad[i] = dm_connect_tcp_from(d, src);
		dm_send_raw(bad[i], "{\"cmd\":\"hello\",\"client\":\"", 25);
	}
	dm_sleep_ms(200);
	/* Every slot is taken: a client arriving now is refused... */
	dm_conn *early = dm_connect_tcp(d);
	send_hello(early, "early");
	expect_refusal(early, "too_many_connections", "client before 1 s");
	dm_close(early);

	/* ...but one that keeps trying gets in once a trickler has waited a
	 * second, while they all keep trickling. */
	double t0 = dm_now_ms(), served_ms = -1;
	int closed[SLOTS] = {0}, nclosed = 0;
	while (dm_now_ms() - t0 < 15000 && (served_ms < 0 || nclosed < SLOTS)) {
		for (int i = 0; i < SLOTS; i++) {
			if (closed[i])
				continue;
			if (dm_wait_closed(bad[i], 0)) {
				closed[i] = 1;
				nclosed++;
				continue;
			}
			dm_send_raw(bad[i], "x", 1);
		}
		if (served_ms < 0) {
			dm_conn *c = dm_connect_tcp(d);
			json_t *r = dm_call_maybe(c, 5000, "{s:s, s:i}", "cmd",
			                          "hello", "version", 1);
			if (r && !strcmp(dm_err_code(r), "")) {
				served_ms = dm_now_ms() - t0;
				json_decref(dm_ok(c, "{s:s}", "cmd", "status"));
			}
			json_decref(r);
			dm_close(c);
		}
		dm_sleep_ms(100);
	}
	if (served_ms < 0)
		fail_msg("%d connections trickling an unfinished hello kept a "
		         "new client out for 15 s",
		         SLOTS);
	if (nclosed < SLOTS)
		fail_msg("%d of %d connections without hello still open 15 s "
		         "after a 3 s hello deadline",
		         SLOTS - nclosed, SLOTS);
	print_message("new client served %.0f ms after the slots were "
	              "taken\n",
	              served_ms);
	for (int i = 0; i < SLOTS; i++) {
		const char *code = dm_unsolicited_error(bad[i]);
		if (!code || (strcmp(code, "hello_timeout") != 0 &&
		              strcmp(code, "too_many_connections") != 0))
			fail_msg("trickler %d closed with %s, want "
			         "hello_timeout or too_many_connections",
			         i, code ? code : "no frame");
	}
	double evicted = dm_metric(d, REFUSED("evicted"));
	double timed_out = dm_metric(d, REFUSED("hello_timeout"));
	if (evicted < 1 || evicted + timed_out != SLOTS)
		fail_msg("/metrics: %g evicted + %g hello_timeout, want %d in "
		         "all, at least one evicted",
		         evicted, timed_out, SLOTS);
	dm_pass();
}

static void test_one_address_holds_a_bounded_share(void **state)
{
	(void)state;
	const char *args[] = {"--max-connections-per-address", "3", NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *mine[3];
	for (int i = 0; i < 3; i++) {
		mine[i] = dm_connect_tcp_from(d, "127.0.0.2");
		json_decref(dm_ok(mine[i], "{s:s, s:i}", "cmd", "hello",
		                  "version", 1));
	}
	dm_conn *extra = dm_connect_tcp_from(d, "127.0.0.2");
	send_hello(extra, "extra");
	json_t *f = NULL;
	if (dm_recv(extra, DM_REPLY_MS, &f, NULL, NULL) != 1)
		fail_msg("the fourth connection from one address got no frame");
	assert_string_equal(dm_err_code(f), "too_many_connections");
	const char *msg = json_string_value(
	        json_object_get(json_object_get(f, "error"), "message"));
	if (!msg || !strstr(msg, "max_connections_per_address"))
		fail_msg("the refusal does not name the limit: %s",
		         dm_dumps(f));
	json_decref(f);
	dm_close(extra);

	/* Another address is served; the three keep working. */
	dm_conn *other = dm_open(d, NULL);
	json_decref(dm_ok(other, "{s:s}", "cmd", "status"));
	for (int i = 0; i < 3; i++)
		json_decref(dm_ok(mine[i], "{s:s}", "cmd", "scene.list"));
	assert_true(dm_metric(d, REFUSED("per_address")) == 1);

	/* A slot the address frees is its own again. */
	dm_close(mine[0]);
	if (!dm_open_when_free(d, "127.0.0.2", 10000))
		fail_msg("a slot freed by an address is not reusable");
	dm_pass();
}

static void test_a_trickled_header_meets_its_deadline(void **state)
{
	(void)state;
	const char *args[] = {"--header-timeout", "1", NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *slow = dm_open(d, NULL);
	dm_conn *fine = dm_open(d, NULL);
	static const char line[] = "{\"cmd\": \"status\", \"id\": 7, \"pad\": "
	                           "\"..............................";
	double t0 = dm_now_ms(), closed_ms = -1;
	for (size_t i = 0; i < sizeof(line) - 1 && closed_ms < 0; i++) {
		dm_send_raw(slow, line + i, 1); /* 10 bytes a second */
		json_decref(dm_ok(fine, "{s:s}", "cmd", "status"));
		if (dm_wait_closed(slow, 100))
			closed_ms = dm_now_ms() - t0;
	}
	if (closed_ms < 0)
		fail_msg("a header trickled for %.0f ms is still being read "
		         "after a 1 s header deadline",
		         dm_now_ms() - t0);
	if (closed_ms < 900)
		fail_msg("the header deadline fired after %.0f ms, before 1 s",
		         closed_ms);
	const char *code = dm_unsolicited_error(slow);
	if (!code || strcmp(code, "header_timeout") != 0)
		fail_msg("the slow header was closed with %s, want "
		         "header_timeout",
		         code ? code : "no frame");
	json_decref(dm_ok(fine, "{s:s}", "cmd", "status"));
	assert_true(dm_metric(d, REFUSED("header_timeout")) == 1);
	dm_pass();
}

static void test_a_silent_connection_meets_the_hello_deadline(void **state)
{
	(void)state;
	const char *args[] = {"--hello-timeout", "1", NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *silent = dm_connect_tcp(d);
	dm_conn *fine = dm_open(d, NULL);
	double t0 = dm_now_ms();
	if (!dm_wait_closed(silent, 10000))
		fail_msg("a connection that never said hello is open 10 s "
		         "after a 1 s hello deadline");
	double ms = dm_now_ms() - t0;
	if (ms < 900)
		fail_msg("the hello deadline fired after %.0f ms", ms);
	const char *code = dm_unsolicited_error(silent);
	if (!code || strcmp(code, "hello_timeout") != 0)
		fail_msg("closed with %s, want hello_timeout",
		         code ? code : "no frame");
	/* An open session is not subject to it. */
	dm_sleep_ms(1200);
	json_decref(dm_ok(fine, "{s:s}", "cmd", "status"));
	assert_true(dm_metric(d, REFUSED("hello_timeout")) == 1);
	dm_pass();
}

int main(void)
{
	const struct CMUnitTest tests[] = {
#define T(f) cmocka_unit_test_setup_teardown(f, dm_setup, dm_teardown)
	        T(test_refused_connections_read_their_frame_then_the_end),
	        T(test_unfinished_hellos_cannot_lock_the_daemon),
	        T(test_one_address_holds_a_bounded_share),
	        T(test_a_trickled_header_meets_its_deadline),
	        T(test_a_silent_connection_meets_the_hello_deadline),
#undef T
	};
	const char *filter = getenv("LUXRAD_TEST_FILTER");
	if (filter)
		cmocka_set_test_filter(filter);
	return cmocka_run_group_tests(tests, NULL, NULL);
}
