/* hello: the smallest radpt method worth benchmarking, written as a plugin
 * to show the interface line by line (README.md, "Your own method").
 *
 * It answers with the ambient term of Cohen, Chen, Wallace & Greenberg
 * (1988): every surface receives the same irradiance, that of a closed room
 * whose area-averaged emission E and reflectance rho are the scene's own,
 *
 *     L_ambient = (sum_i Le_i A_i / sum_i A_i) / (1 - rho_avg),
 *     L_s = Le_s + rho_s L_ambient        (per band),
 *
 * which is exact in a furnace (one material everywhere, a closed scene) and
 * a crude guess elsewhere.  One step computes it; the image shows each
 * pixel's first hit.
 *
 * Build against an installed radpt (make install):
 *     cc -std=c11 -shared -fPIC -O2 hello.c -o hello.so $(pkg-config --cflags --libs radpt)
 * and run it:
 *     radpt render scenes/cornell.scene --plugin ./hello.so --method hello -o hello.exr */
#include <radpt/radpt.h> /* the one header a plugin includes */

#include <stdlib.h>
#include <string.h>

/* The ABI this plugin was built for: radpt checks it before anything else. */
RP_PLUGIN_DECLARE_ABI;

/* A method's state: radpt allocates state_size zeroed bytes and hands them
 * to init, step, estimate and fini. */
typedef struct hello_state {
    const rp_scene *scene; /* borrowed: lives as long as the solver */
    unsigned want;         /* RP_WANT_IMAGE and/or RP_WANT_SURFACES */
    size_t nbands, nsurfaces;
    double *L;             /* nsurfaces x nbands: the answer per surface */
    rp_raycast *rc;        /* for the image: first hits through the camera */
    int solved;
} hello_state;

/* Options are "--name value" on the command line and "name=value" in
 * bench method specs.  Each has a spec: its name, its argument, one line of
 * help (radpt help hello prints it) and its default as text (which
 * rp_options_double and friends fall back to).  The list ends in {NULL}. */
static const rp_option_spec hello_options[] = {
    {"scale", "S", "multiplies the ambient term (1: Cohen et al.'s estimate)", "1"},
    {NULL, NULL, NULL, NULL}
};

static void hello_fini(void *state)
{
    /* fini must accept a state that init left half built (or zeroed). */
    hello_state *s = state;
    free(s->L);
    rp_raycast_destroy(s->rc);
}

static rp_status hello_init(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    hello_state *s = state;
    s->scene = scene;
    s->want = o->want;
    s->nbands = rp_scene_nbands(scene);
    s->nsurfaces = rp_scene_nsurfaces(scene);
    double scale = 1;
    /* Parses "--scale" (or its default); a bad value is RP_ERR_INPUT with
     * a message that names the option: radpt prints it and exits 2. */
    rp_status st = rp_options_double(o, "scale", 0, 1e6, &scale, err);
    if (st != RP_OK)
        return st;
    s->L = calloc(s->nsurfaces * s->nbands + 1, sizeof *s->L);
    if (!s->L)
        return rp_error_set(err, RP_ERR_NOMEM, "hello: out of memory");
    if (s->want & RP_WANT_IMAGE) {
        if (!rp_scene_camera(scene))
            return rp_error_set(err, RP_ERR_INPUT, "hello: the scene has no camera");
        /* No mesh: hits name faces and surfaces only. */
        if ((st = rp_raycast_create(scene, NULL, &s->rc, err)) != RP_OK)
            return st;
    }
    /* The ambient term, per band. */
    const rp_surface *surf = rp_scene_surfaces(scene);
    const rp_material *mat = rp_scene_materials(scene);
    for (size_t b = 0; b < s->nbands; b++) {
        double area = 0, emitted = 0, reflected = 0;
        for (size_t i = 0; i < s->nsurfaces; i++) {
            const rp_material *m = &mat[surf[i].material];
            area += surf[i].area;
            emitted += m->Le[b] * surf[i].area;
            reflected += m->rho[b] * surf[i].area;
        }
        double rho_avg = area > 0 ? reflected / area : 0;
        double ambient = rho_avg < 1 && area > 0 ? scale * (emitted / area) / (1 - rho_avg) : 0;
        for (size_t i = 0; i < s->nsurfaces; i++) {
            const rp_material *m = &mat[surf[i].material];
            s->L[i * s->nbands + b] = m->Le[b] + m->rho[b] * ambient;
        }
    }
    return RP_OK;
}

/* One step of work.  The harness calls step until the method says it has
 * converged (info->converged), a budget runs out, or the user stops it;
 * long steps should poll rp_options_cancelled.  This method did its work in
 * init, so its one step only says so. */
static rp_status hello_step(void *state, rp_step_info *info, rp_error *err)
{
    (void)err;
    hello_state *s = state;
    info->iterations = s->solved ? 0 : 1; /* what this step did */
    s->solved = 1;
    info->converged = 1;                  /* its own rule is met */
    info->progress = 1;
    info->memory = (double)(s->nsurfaces * s->nbands * sizeof *s->L);
    return RP_OK;
}

/* The answer so far, in radiance (W sr^-1 m^-2) per band.  The harness
 * allocates; fill what is non-NULL.  estimate may be called any number of
 * times (at checkpoints) and must not change the state. */
static rp_status hello_estimate(const void *state, rp_estimate *e, rp_error *err)
{
    (void)err;
    const hello_state *s = state;
    const size_t nb = s->nbands;
    if (e->surface_radiance)
        memcpy(e->surface_radiance, s->L, s->nsurfaces * nb * sizeof *s->L);
    if (e->surface_stderr) /* deterministic: no standard error */
        memset(e->surface_stderr, 0, s->nsurfaces * nb * sizeof *e->surface_stderr);
    if (e->radiance) {
        const rp_camera *cam = rp_scene_camera(s->scene);
        rp_camera_frame f;
        rp_camera_frame_init(&f, cam);
        for (uint32_t y = 0; y < cam->height; y++)
            for (uint32_t x = 0; x < cam->width; x++) {
                /* one ray through the pixel's centre; row-major from the
                 * top-left, band fastest */
                rp_hit hit;
                rp_vec3 d = rp_camera_direction(&f, x + 0.5, y + 0.5);
                int found = rp_ray_closest(s->rc, f.eye, d, INFINITY, &hit) && hit.front;
                float *px = e->radiance + ((size_t)y * cam->width + x) * nb;
                for (size_t b = 0; b < nb; b++)
                    px[b] = found ? (float)s->L[hit.surface * nb + b] : 0.0f;
            }
    }
    if (e->variance)
        memset(e->variance, 0, (size_t)rp_scene_camera(s->scene)->width * rp_scene_camera(s->scene)->height * nb *
                                   sizeof *e->variance);
    e->samples = s->solved;
    return RP_OK;
}

/* The type table: what radpt knows of the method.  Fields left out are 0
 * or NULL: no checkpoints (save, load), not Monte Carlo (one seed in
 * benches), not split over MPI ranks (it runs on rank 0). */
static const rp_solver_type hello_type = {
    .name = "hello",
    .summary = "the ambient term of Cohen et al. 1988 for every surface (a plugin example)",
    .options = hello_options,
    .state_size = sizeof(hello_state),
    .init = hello_init,
    .step = hello_step,
    .estimate = hello_estimate,
    .fini = hello_fini,
    .iteration_name = "solves",
};

/* The entry point: radpt calls it once, after checking the ABI. */
rp_status rp_plugin_init(const rp_plugin_host *host, int abi, rp_error *err)
{
    (void)abi; /* equal to RP_PLUGIN_ABI: radpt checked rp_plugin_abi */
    return host->register_type(host, &hello_type, err);
}
