/* Scene loading for commands and experiments. */
#ifndef RP_LOAD_H
#define RP_LOAD_H

#include "geometry/scene.h"
#include "geometry/status.h"

/* The one scene loader of every command and experiment: loads path (format 1 or .obj),
 * gives it the camera words of --camera when camera is not NULL (before
 * anything hashes the scene), prints each of the scene's warnings once on
 * stderr as "radpt: warning: FILE:LINE: ...", and, when need_camera is set
 * and the scene has no camera, sets the default camera (default_camera.h)
 * and prints it as the --camera words that give it back.  Bad --camera
 * words are RP_ERR_INPUT ("--camera: ..."), checked before the scene is
 * read. */
rp_status rp_load_scene(const char *path, const char *camera, int need_camera, rp_scene **out,
                            rp_error *err);

#endif
