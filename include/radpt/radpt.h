/* radpt's public interface, installed as <radpt/radpt.h> (make install):
 * everything a plugin (solvers/plugin.h) or a program using libradpt may
 * call.  Plugins include this one header.
 *
 *   geometry/vec.h       three-vectors
 *   geometry/status.h    rp_status, rp_error
 *   geometry/scene.h     the scene: bands, materials, surfaces, faces, camera
 *   geometry/mesh.h      elements of a subdivided scene
 *   geometry/raycast.h   ray casting (Embree), offsets that do not depend on scale
 *   geometry/sample.h    area and emitter sampling
 *   geometry/camera.h    pinhole rays and projection
 *   solvers/comm.h       the communicator of a method split over MPI ranks
 *   solvers/solver.h     the method interface (rp_solver_type) and options
 *   solvers/plugin.h     the plugin entry point and ABI version */
#ifndef RADPT_H
#define RADPT_H

#include "geometry/vec.h"
#include "geometry/status.h"
#include "geometry/scene.h"
#include "geometry/mesh.h"
#include "geometry/raycast.h"
#include "geometry/sample.h"
#include "geometry/camera.h"
#include "solvers/comm.h"
#include "solvers/solver.h"
#include "solvers/plugin.h"


#endif
