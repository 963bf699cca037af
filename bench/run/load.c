/* The one scene loader of every command and experiment (load.h). */
#include "bench/run/load.h"

#include <stdio.h>

#include "geometry/default_camera.h"

rp_status rp_load_scene(const char *path, const char *camera, int need_camera, rp_scene **out, rp_error *err)
{
    *out = NULL;
    rp_camera given;
    rp_status st;
    if (camera && (st = rp_camera_parse(camera, "--camera", &given, err)) != RP_OK)
        return st;
    rp_scene *scene = NULL;
    if ((st = rp_scene_load(path, &scene, err)) != RP_OK)
        return st;
    for (size_t i = 0; i < rp_scene_nwarnings(scene); i++)
        fprintf(stderr, "radpt: warning: %s\n", rp_scene_warning(scene, i));
    if (camera) {
        st = rp_scene_set_camera(scene, &given, err);
    } else if (need_camera && !rp_scene_camera(scene)) {
        rp_camera def;
        st = rp_scene_default_camera(scene, &def, err);
        if (st == RP_OK)
            st = rp_scene_set_camera(scene, &def, err);
        if (st == RP_OK) {
            char words[512];
            rp_camera_format(&def, words, sizeof words);
            fprintf(stderr, "radpt: %s has no camera; using the default, which is --camera \"%s\"\n", path,
                    words);
        }
    }
    if (st != RP_OK) {
        rp_scene_destroy(scene);
        return st;
    }
    *out = scene;
    return RP_OK;
}
