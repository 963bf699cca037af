/* radpt info SCENE [--json] [--camera WORDS]: what a scene holds, as the
 * solvers see it, with the warnings its reading raised and, for a scene
 * without a camera, the default camera a render would use. */
#include <stdio.h>
#include <stdlib.h>

#include "geometry/default_camera.h"
#include "geometry/mesh.h"
#include "geometry/scene.h"
#include "bench/cli/cli.h"
#include "bench/cli/commands.h"

static const char *band_kind_name(rp_band_kind k)
{
    switch (k) {
    case RP_BANDS_GREY: return "grey";
    case RP_BANDS_RGB: return "rgb";
    case RP_BANDS_SPECTRAL: return "spectral";
    }
    return "?";
}

static const char *surface_kind_name(rp_surface_kind k)
{
    switch (k) {
    case RP_SURFACE_TRIANGLE: return "triangle";
    case RP_SURFACE_QUAD: return "quad";
    case RP_SURFACE_BOX: return "box";
    case RP_SURFACE_MESH: return "mesh";
    }
    return "?";
}

static void json_array(FILE *f, const double *v, size_t n)
{
    fputc('[', f);
    for (size_t i = 0; i < n; i++)
        fprintf(f, "%s%.10g", i ? ", " : "", v[i]);
    fputc(']', f);
}

/* The words of the camera a render would use when the scene has none
 * (empty when it has one or none can be made). */
static void default_words(const rp_scene *scene, char *words, size_t len)
{
    rp_camera def;
    words[0] = '\0';
    if (!rp_scene_camera(scene) && rp_scene_default_camera(scene, &def, NULL) == RP_OK)
        rp_camera_format(&def, words, len);
}

static void print_json(const rp_scene *scene, const char *path, int closed, const rp_mesh *mesh)
{
    size_t nb = rp_scene_nbands(scene);
    const rp_material *mats = rp_scene_materials(scene);
    const rp_surface *surf = rp_scene_surfaces(scene);
    double *power = calloc(nb, sizeof *power);
    char hash[17];
    rp_scene_hash(scene, hash);

    printf("{\"scene\": ");
    rp_json_string(stdout, path);
    printf(", \"hash\": \"%s\", \"bands\": {\"kind\": \"%s\", \"count\": %zu", hash,
           band_kind_name(rp_scene_band_kind(scene)), nb);
    if (rp_scene_wavelengths(scene)) {
        printf(", \"wavelengths_nm\": ");
        json_array(stdout, rp_scene_wavelengths(scene), nb);
    }
    printf("}");
    const rp_camera *cam = rp_scene_camera(scene);
    if (cam)
        printf(", \"camera\": {\"eye\": [%.10g, %.10g, %.10g], \"look\": [%.10g, %.10g, %.10g], "
               "\"up\": [%.10g, %.10g, %.10g], \"fov_deg\": %.10g, \"width\": %u, \"height\": %u}",
               cam->eye.x, cam->eye.y, cam->eye.z, cam->look.x, cam->look.y, cam->look.z,
               cam->up.x, cam->up.y, cam->up.z, cam->fov_deg, cam->width, cam->height);
    else
        printf(", \"camera\": null");
    char words[512];
    default_words(scene, words, sizeof words);
    if (words[0]) {
        printf(", \"default_camera\": ");
        rp_json_string(stdout, words);
    }
    printf(", \"warnings\": [");
    for (size_t i = 0; i < rp_scene_nwarnings(scene); i++) {
        printf("%s", i ? ", " : "");
        rp_json_string(stdout, rp_scene_warning(scene, i));
    }
    printf("], \"materials\": [");
    for (size_t i = 0; i < rp_scene_nmaterials(scene); i++) {
        printf("%s{\"name\": ", i ? ", " : "");
        rp_json_string(stdout, mats[i].name);
        printf(", \"reflect\": ");
        json_array(stdout, mats[i].rho, nb);
        printf(", \"emit\": ");
        json_array(stdout, mats[i].Le, nb);
        printf("}");
    }
    printf("], \"surfaces\": [");
    for (size_t i = 0; i < rp_scene_nsurfaces(scene); i++) {
        rp_scene_surface_power(scene, (uint32_t)i, power);
        printf("%s{\"name\": ", i ? ", " : "");
        rp_json_string(stdout, surf[i].name);
        printf(", \"material\": ");
        rp_json_string(stdout, mats[surf[i].material].name);
        printf(", \"kind\": \"%s\", \"faces\": %u, \"area\": %.12g, \"emitted_power\": ",
               surface_kind_name(surf[i].kind), surf[i].nfaces, surf[i].area);
        json_array(stdout, power, nb);
        if (mesh) {
            uint32_t first, count;
            rp_mesh_surface_elements(mesh, (uint32_t)i, &first, &count);
            printf(", \"elements\": %u", count);
        }
        printf("}");
    }
    printf("], \"faces\": %zu, \"vertices\": %zu, \"total_area\": %.12g, \"closed\": %s",
           rp_scene_nfaces(scene), rp_scene_nvertices(scene), rp_scene_total_area(scene),
           closed > 0 ? "true" : closed == 0 ? "false" : "null");
    if (mesh) {
        rp_mesh_quality q;
        rp_mesh_quality_get(mesh, &q);
        printf(", \"elements\": {\"count\": %zu, \"vertices\": %zu, \"target\": %d, "
               "\"aspect_min\": %.6g, \"aspect_mean\": %.6g, \"aspect_max\": %.6g, "
               "\"area_min\": %.6g, \"area_max\": %.6g}",
               rp_mesh_nelements(mesh), rp_mesh_nvertices(mesh), (int)(RP_MESH_DEFAULT_COUNT + rp_scene_nfaces(scene)),
               q.min_aspect, q.mean_aspect, q.max_aspect, q.min_area, q.max_area);
    }
    printf("}\n");
    free(power);
}

static void print_text(const rp_scene *scene, const char *path, int closed, const rp_mesh *mesh)
{
    size_t nb = rp_scene_nbands(scene);
    const rp_material *mats = rp_scene_materials(scene);
    const rp_surface *surf = rp_scene_surfaces(scene);
    double *power = calloc(nb, sizeof *power);
    char hash[17];
    rp_scene_hash(scene, hash);

    printf("scene     %s (hash %s)\n", path, hash);
    printf("bands     %s, %zu", band_kind_name(rp_scene_band_kind(scene)), nb);
    if (rp_scene_wavelengths(scene))
        printf(" (%g to %g nm)", rp_scene_wavelengths(scene)[0], rp_scene_wavelengths(scene)[nb - 1]);
    printf("\n");
    const rp_camera *cam = rp_scene_camera(scene);
    if (cam)
        printf("camera    eye (%g, %g, %g) look (%g, %g, %g) up (%g, %g, %g) fov %g deg, %u x %u\n",
               cam->eye.x, cam->eye.y, cam->eye.z, cam->look.x, cam->look.y, cam->look.z,
               cam->up.x, cam->up.y, cam->up.z, cam->fov_deg, cam->width, cam->height);
    else {
        char words[512];
        default_words(scene, words, sizeof words);
        printf("camera    none; render uses the default --camera \"%s\"\n", words);
    }
    printf("\n%-20s %-12s %-8s %7s %14s %9s  %s\n", "surface", "material", "kind", "faces", "area",
           "elements", "emitted power (W per band)");
    for (size_t i = 0; i < rp_scene_nsurfaces(scene); i++) {
        uint32_t first = 0, count = 0;
        if (mesh)
            rp_mesh_surface_elements(mesh, (uint32_t)i, &first, &count);
        char sn[512], mn[512];
        printf("%-20s %-12s %-8s %7u %14.6f %9u ", rp_cli_name(surf[i].name, sn, sizeof sn),
               rp_cli_name(mats[surf[i].material].name, mn, sizeof mn), surface_kind_name(surf[i].kind),
               surf[i].nfaces, surf[i].area, count);
        if (mats[surf[i].material].emitter) {
            rp_scene_surface_power(scene, (uint32_t)i, power);
            for (size_t b = 0; b < nb && b < 8; b++)
                printf(" %.6g", power[b]);
            if (nb > 8)
                printf(" ...");
        } else {
            printf(" -");
        }
        printf("\n");
    }
    printf("\ntotal     %zu surfaces, %zu faces, %zu vertices, area %.6f\n", rp_scene_nsurfaces(scene),
           rp_scene_nfaces(scene), rp_scene_nvertices(scene), rp_scene_total_area(scene));
    printf("closed    %s\n", closed > 0 ? "yes" : closed == 0 ? "no (open)" : "undecided");
    if (mesh) {
        rp_mesh_quality q;
        rp_mesh_quality_get(mesh, &q);
        printf("elements  %zu (default subdivision, target %d: one per face and %d more), %zu vertices\n", rp_mesh_nelements(mesh),
               (int)(RP_MESH_DEFAULT_COUNT + rp_scene_nfaces(scene)), RP_MESH_DEFAULT_COUNT, rp_mesh_nvertices(mesh));
        printf("quality   aspect ratio min %.3f mean %.3f max %.3f (1 is best); area %.4g to %.4g\n",
               q.min_aspect, q.mean_aspect, q.max_aspect, q.min_area, q.max_area);
    }
    if (rp_scene_nwarnings(scene) > 0)
        printf("warnings  %zu (on stderr, and in --json)\n", rp_scene_nwarnings(scene));
    free(power);
}

int rp_cmd_info(int argc, char **argv)
{
    rp_cli cli = {.command = "info"};
    int rc = rp_cli_parse(&cli, argc, argv, NULL, 0);
    if (rc)
        return rc;
    rp_error err;
    rp_scene *scene = NULL;
    rp_status st = rp_load_scene(cli.scene, cli.camera, 0, &scene, &err);
    if (st != RP_OK)
        return rp_cli_fail(st, &err);
    int closed = rp_scene_is_closed(scene);
    rp_mesh *mesh = NULL;
    rp_mesh_params params = {.size = sizeof params};
    st = rp_mesh_create(scene, &params, &mesh, &err);
    if (st != RP_OK) {
        rp_scene_destroy(scene);
        return rp_cli_fail(st, &err);
    }
    if (cli.json)
        print_json(scene, cli.scene, closed, mesh);
    else
        print_text(scene, cli.scene, closed, mesh);
    rp_mesh_destroy(mesh);
    rp_scene_destroy(scene);
    return 0;
}
