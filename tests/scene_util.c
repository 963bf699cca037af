/* Scenes for tests (see scene_util.h). */
#include "scene_util.h"

#include <criterion/criterion.h>
#include <stdio.h>

rp_scene *rp_test_load(const char *rel)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", RP_SOURCE_DIR, rel);
    rp_scene *s = NULL;
    rp_error err = {""};
    rp_status st = rp_scene_load(path, &s, &err);
    cr_assert_eq(st, RP_OK, "scene %s: %s", rel, err.message);
    return s;
}

rp_scene *rp_test_parse_in(const char *text, const char *dir)
{
    rp_scene *s = NULL;
    rp_error err = {""};
    rp_status st = rp_scene_parse(text, "test.scene", dir, &s, &err);
    cr_assert_eq(st, RP_OK, "scene: %s", err.message);
    return s;
}

rp_scene *rp_test_parse(const char *text)
{
    return rp_test_parse_in(text, NULL);
}
