/* The fuzz corpus, replayed by `make test`: every input under
 * tests/fuzz/scene/ and tests/fuzz/mesh/ (what `make fuzz` has found
 * interesting) and every crash input kept under tests/fuzz/crashes/
 * ("scene-*" or "mesh-*") goes through the fuzz targets' own entry points,
 * compiled in here under other names.  Each must return without a crash;
 * under `make asan` a memory error fails the run. */
#include <criterion/criterion.h>
#include <dirent.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define LLVMFuzzerTestOneInput rp_fuzz_mesh_one
#include "fuzz/fuzz_mesh.c"
#undef LLVMFuzzerTestOneInput
#define LLVMFuzzerTestOneInput rp_fuzz_scene_one
#include "fuzz/fuzz_scene.c"
#undef LLVMFuzzerTestOneInput

typedef int (*fuzz_fn)(const uint8_t *, size_t);

/* Feeds every file of dir whose name starts with prefix ("" for all) to
 * fn; returns how many. */
static size_t replay(const char *dir, const char *prefix, fuzz_fn fn)
{
    DIR *d = opendir(dir);
    cr_assert_not_null(d, "%s: missing", dir);
    size_t n = 0;
    struct dirent *e;
    while ((e = readdir(d))) {
        if (e->d_name[0] == '.' || strncmp(e->d_name, prefix, strlen(prefix)) != 0)
            continue;
        char path[1024];
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        FILE *f = fopen(path, "rb");
        cr_assert_not_null(f, "%s", path);
        fseek(f, 0, SEEK_END);
        long len = ftell(f);
        fseek(f, 0, SEEK_SET);
        uint8_t *buf = malloc((size_t)len + 1);
        cr_assert_not_null(buf);
        cr_assert_eq(fread(buf, 1, (size_t)len, f), (size_t)len);
        fclose(f);
        cr_assert_eq(fn(buf, (size_t)len), 0, "%s", path);
        free(buf);
        n++;
    }
    closedir(d);
    return n;
}

Test(fuzz_corpus, scene_inputs_replay)
{
    size_t n = replay(RP_SOURCE_DIR "/tests/fuzz/scene", "", rp_fuzz_scene_one);
    n += replay(RP_SOURCE_DIR "/tests/fuzz/crashes", "scene-", rp_fuzz_scene_one);
    cr_expect_gt(n, 100, "the scene corpus has %zu inputs", n);
}

Test(fuzz_corpus, mesh_inputs_replay)
{
    size_t n = replay(RP_SOURCE_DIR "/tests/fuzz/mesh", "", rp_fuzz_mesh_one);
    size_t crashes = replay(RP_SOURCE_DIR "/tests/fuzz/crashes", "mesh-", rp_fuzz_mesh_one);
    cr_expect_gt(n, 100, "the mesh corpus has %zu inputs", n);
    cr_expect_geq(crashes, 1, "the absurd-count OFF header that fuzz_mesh found is kept");
}
