/*
 * generated.c -- scenes from luxrad-scenegen for the engine tests
 * (generated.h).
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

#include <cmocka.h>

#include "generated.h"
#include "sceneio.h"

rad_scene *generated_scene(const char *args)
{
	char path[] = "/tmp/luxrad-scene-XXXXXX.glb", cmd[512];
	int fd = mkstemps(path, 4);
	assert_true(fd >= 0);
	close(fd);
	snprintf(cmd, sizeof(cmd),
	         "'%s/luxrad-scenegen' %s -o '%s' 2>/dev/null",
	         LUXRAD_BINARY_DIR, args, path);
	assert_int_equal(system(cmd), 0);
	rad_scene *s = NULL;
	rad_error err;
	if (sio_load_file(path, &s, NULL, &err) != RAD_OK)
		fail_msg("%s", err.msg);
	unlink(path);
	return s;
}
