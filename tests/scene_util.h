/* Scenes for tests: loaded from the source tree or parsed from text, with a
 * Criterion assertion (naming the file and the parser's message) when the
 * scene is refused. */
#ifndef RP_TEST_SCENE_UTIL_H
#define RP_TEST_SCENE_UTIL_H

#include "geometry/scene.h"

/* rel is relative to the source directory: "scenes/cornell.scene". */
rp_scene *rp_test_load(const char *rel);
/* A scene from text; includes and meshes resolve against dir (NULL: the
 * current directory). */
rp_scene *rp_test_parse_in(const char *text, const char *dir);
rp_scene *rp_test_parse(const char *text);

#endif
