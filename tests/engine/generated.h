/*
 * generated.h -- scenes from luxrad-scenegen for the engine tests.
 */
#ifndef LUXRAD_TESTS_GENERATED_H
#define LUXRAD_TESTS_GENERATED_H

#include "rad.h"

/*
 * Run `luxrad-scenegen ARGS` (a kind and its options, as on the command
 * line) into a temporary .glb, load it through the importer and remove
 * the file.  Fails the calling cmocka test on any error.
 */
rad_scene *generated_scene(const char *args);

#endif
