/* A camera for a scene that has none: the whole scene framed from the OBJ
 * convention's viewpoint (y up, looking along -z), and from inside when the
 * scene is a room seen only from behind its walls from out there. */
#ifndef RP_DEFAULT_CAMERA_H
#define RP_DEFAULT_CAMERA_H

#include <stddef.h>

#include "scene.h"

#define RP_DEFAULT_CAMERA_FOV 40.0  /* degrees, vertical */
#define RP_DEFAULT_CAMERA_SIZE 256  /* pixels, square */

/* The default camera of scene (its own camera is not looked at).  Its
 * numbers are rounded to what rp_camera_format prints, so the printed words
 * give back this camera exactly.  Deterministic; costs a few dozen rays
 * against every face (no acceleration structure). */
rp_status rp_scene_default_camera(const rp_scene *scene, rp_camera *out, rp_error *err);

/* The camera as words rp_camera_parse reads back exactly: "eye X Y Z look
 * X Y Z up X Y Z fov F size W H", each number in the fewest digits that
 * round-trip.  Returns the length snprintf would (truncated to len). */
int rp_camera_format(const rp_camera *cam, char *buf, size_t len);

#endif
