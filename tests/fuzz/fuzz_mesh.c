/* libFuzzer harness for mesh import through the CGAL shim (make fuzz).  The
 * first byte picks the format (OBJ, OFF, PLY); the rest is the file. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

#include "geometry/cgal/import.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const char *const ext[3] = {"obj", "off", "ply"};
    if (size < 1)
        return 0;
    char path[64];
    snprintf(path, sizeof path, "/tmp/radpt-fuzz-%d.%s", (int)getpid(), ext[data[0] % 3]);
    FILE *f = fopen(path, "wb");
    if (!f)
        return 0;
    fwrite(data + 1, 1, size - 1, f);
    fclose(f);
    rp_tri_mesh m;
    char msg[512];
    if (rp_cgal_read_mesh(path, 0, &m, msg, sizeof msg) == 0)
        rp_tri_mesh_free(&m);
    unlink(path);
    return 0;
}
