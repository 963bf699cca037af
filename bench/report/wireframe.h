/* Mesh overlays: a radiosity mesh's element boundaries drawn over an image
 * seen by the scene's camera, so a reader sees where the elements went.
 *
 * The boundaries come from an item buffer (Weghorst, Hooper & Greenberg
 * 1984: the element each pixel sees, found by casting the camera's rays
 * against the mesh), rendered at 3 x 3 sub-pixels: a sub-pixel whose
 * element differs from its right or lower neighbour's lies on a boundary,
 * and a pixel is drawn in the line colour in proportion to the share of
 * its sub-pixels that do.  Hidden edges are never drawn, since only
 * visible elements are in the buffer. */
#ifndef RP_WIREFRAME_H
#define RP_WIREFRAME_H

#include <stddef.h>

#include "bench/report/image.h"
#include "geometry/mesh.h"
#include "geometry/scene.h"
#include "geometry/status.h"

/* Writes path (PNG): the scene's camera view of rgb (3 planes of linear
 * radiance, width x height of the camera; NULL: a uniform grey), its
 * exposure (NULL: automatic), with mesh's element boundaries in yellow.
 * The scene must have a camera. */
rp_status rp_wireframe_png(const char *path, const rp_scene *scene, const rp_mesh *mesh, const float *const rgb[3],
                           const rp_exposure *exposure, rp_error *err);

#endif
