/*
 * config_int.h -- the key table of luxradd's configuration, shared by
 * config.c (the table, defaults, values, checks) and config_cli.c (the
 * config file, the flags, --help).
 */
#ifndef LUXRAD_SRV_CONFIG_INT_H
#define LUXRAD_SRV_CONFIG_INT_H

#include <stddef.h>

#include "config.h"

#define CFG_MAX_KEYS 64 /* rows of the table, at most (asserted) */

typedef enum key_type {
	K_TCP,     /* host:port, or "none" / "" = off (char array) */
	K_UNIX,    /* socket path, or "none" / "" = off (char array) */
	K_DIR,     /* directory path, required (char array) */
	K_FILE,    /* file path, or "none" / "" = none (char array) */
	K_BOOL,    /* int 0/1 */
	K_INT,     /* int within [lo, hi] */
	K_SIZE,    /* size_t bytes within [lo, hi], K/M/G/T suffixes */
	K_SECONDS, /* double seconds within [lo, hi], s/m/h suffixes */
	K_REAL,    /* double within [lo, hi] */
	K_LEVEL,   /* srv_log_level */
	K_CHOICE,  /* an enum: the index of one of choices */
	K_MODBUS,  /* a modbus_* key: parsed and printed by mb_config_* */
} key_type;

typedef struct cfg_key {
	const char *name;    /* file key; the flag is --name with '-' for '_' */
	key_type type;       /* how the value is parsed */
	size_t off, size;    /* the field in srv_config, its sizeof */
	double lo, hi;       /* accepted range (numbers) */
	const char *metavar; /* for --help */
	const char *example; /* a value worth showing */
	const char *help;    /* one line */
} cfg_key;

/* The table (*n rows). */
const cfg_key *cfg_keys(size_t *n);
/* The key named name (len bytes; dashes match underscores), or NULL. */
const cfg_key *cfg_find_key(const char *name, size_t len);
/* Parse and range-check one value into c: 0, or -1 with msg. */
int cfg_set_value(srv_config *c, const cfg_key *k, const char *v, char *msg,
                  size_t msglen);
/* A path made absolute against the working directory: 0, or -1 with
 * msg. */
int cfg_set_path(char *dst, size_t size, const char *v, char *msg,
                 size_t msglen);
/* A value as the file would write it. */
void cfg_fmt_value(const srv_config *c, const cfg_key *k, char *buf,
                   size_t len);

#endif
