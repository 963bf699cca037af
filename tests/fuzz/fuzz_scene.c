/* libFuzzer harness for the scene parser (make fuzz).  Includes and meshes
 * resolve against a directory that does not exist, so they fail cleanly. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "geometry/scene.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char *text = malloc(size + 1);
    if (!text)
        return 0;
    memcpy(text, data, size);
    text[size] = '\0';
    rp_scene *scene = NULL;
    rp_error err;
    if (rp_scene_parse(text, "fuzz.scene", "/nonexistent-radpt-fuzz", &scene, &err) == RP_OK)
        rp_scene_destroy(scene);
    free(text);
    return 0;
}
