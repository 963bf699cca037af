/* Open MPI as a layer (mpi.h). */
#define _GNU_SOURCE /* sched_getaffinity, CPU_COUNT */
#include "bench/run/mpi.h"

#include "bench/report/files.h"

#include <fcntl.h>
#include <sched.h>
#include <limits.h>
#include <mpi.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

static int started;        /* MPI_Init was called */
static int world_rank, world_size = 1;
static int saved_stderr = -1; /* the real standard error of a rank > 0 */
static FILE *captured;     /* what a rank > 0 wrote to stderr */

/* MPI counts are ints: long buffers go in pieces. */
#define RP_MPI_PIECE (1 << 28)

static void comm_reduce(const rp_comm *c, double *buf, size_t n, MPI_Op op)
{
    (void)c;
    while (n > 0) {
        int k = n > RP_MPI_PIECE ? RP_MPI_PIECE : (int)n;
        MPI_Allreduce(MPI_IN_PLACE, buf, k, MPI_DOUBLE, op, MPI_COMM_WORLD);
        buf += k;
        n -= (size_t)k;
    }
}

static void comm_sum(const rp_comm *c, double *buf, size_t n)
{
    comm_reduce(c, buf, n, MPI_SUM);
}

static void comm_max(const rp_comm *c, double *buf, size_t n)
{
    comm_reduce(c, buf, n, MPI_MAX);
}

static void comm_bcast(const rp_comm *c, void *buf, size_t bytes, int root)
{
    (void)c;
    unsigned char *p = buf;
    while (bytes > 0) {
        int k = bytes > RP_MPI_PIECE ? RP_MPI_PIECE : (int)bytes;
        MPI_Bcast(p, k, MPI_BYTE, root, MPI_COMM_WORLD);
        p += k;
        bytes -= (size_t)k;
    }
}

static rp_comm world = {.sum = comm_sum, .max = comm_max, .bcast = comm_bcast};

static int launched_by_mpirun(void)
{
    const char *v = getenv("OMPI_COMM_WORLD_SIZE");
    return v && *v;
}

int rp_mpi_start(int *argc, char ***argv)
{
    if (!launched_by_mpirun())
        return 0;
    int provided = 0;
    /* Threads (OpenMP) never call MPI: only the main thread does. */
    if (MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS) {
        fprintf(stderr, "radpt: MPI_Init_thread failed\n");
        return 1;
    }
    started = 1;
    MPI_Comm_rank(MPI_COMM_WORLD, &world_rank);
    MPI_Comm_size(MPI_COMM_WORLD, &world_size);
    world.rank = world_rank;
    world.size = world_size;
    /* mpirun binds each rank to one core when K <= 2: say so where that
     * leaves cores idle (threads follow the binding: OpenMP's default
     * counts the cores a process may use) */
    cpu_set_t cpus;
    long online = sysconf(_SC_NPROCESSORS_ONLN);
    if (world_rank == 0 && sched_getaffinity(0, sizeof cpus, &cpus) == 0 &&
        (long)CPU_COUNT(&cpus) * world_size < online)
        fprintf(stderr, "radpt: note: each of the %d ranks may use %d of this machine's %ld cores (mpirun "
                        "binds ranks to cores); mpirun --bind-to none lets threads use the rest\n",
                world_size, CPU_COUNT(&cpus), online);
    if (world_rank != 0) {
        rp_files_discard(1);
        fflush(NULL);
        int null = open("/dev/null", O_WRONLY | O_CLOEXEC);
        if (null >= 0) {
            dup2(null, STDOUT_FILENO);
            close(null);
        }
        captured = tmpfile();
        saved_stderr = dup(STDERR_FILENO);
        if (captured && saved_stderr >= 0)
            dup2(fileno(captured), STDERR_FILENO);
    }
    return 0;
}

const rp_comm *rp_mpi_world(void)
{
    return started && world_size > 1 ? &world : NULL;
}

int rp_mpi_rank(void)
{
    return world_rank;
}

int rp_mpi_size(void)
{
    return world_size;
}

/* Copies what this rank wrote to stderr to the real stderr. */
static void show_captured(void)
{
    if (!captured || saved_stderr < 0)
        return;
    fflush(stderr);
    rewind(captured);
    char buf[4096];
    size_t n;
    while ((n = fread(buf, 1, sizeof buf, captured)) > 0)
        if (write(saved_stderr, buf, n) < 0)
            break;
}

int rp_mpi_finish(int code)
{
    if (!started)
        return code;
    int *codes = calloc((size_t)world_size, sizeof *codes);
    int result = code;
    if (codes) {
        MPI_Request req;
        MPI_Iallgather(&code, 1, MPI_INT, codes, 1, MPI_INT, MPI_COMM_WORLD, &req);
        /* Poll with a sleep: a blocking collective would spin a core
         * while rank 0 works alone (a method that does not split). */
        int done = 0;
        while (MPI_Test(&req, &done, MPI_STATUS_IGNORE) == MPI_SUCCESS && !done) {
            struct timespec ts = {0, 2000000};
            nanosleep(&ts, NULL);
        }
        int decider = -1;
        for (int r = 0; r < world_size && decider < 0; r++)
            if (codes[r] != 0)
                decider = r;
        result = decider >= 0 ? codes[decider] : 0;
        if (decider >= 0 && decider == world_rank && world_rank != 0)
            show_captured();
        free(codes);
    }
    fflush(NULL);
    MPI_Finalize();
    if (captured)
        fclose(captured);
    return result;
}

void rp_mpi_describe(char *buf, size_t n)
{
    char lib[MPI_MAX_LIBRARY_VERSION_STRING] = "";
    int len = 0;
    MPI_Get_library_version(lib, &len); /* allowed before MPI_Init */
    char *nl = strchr(lib, ',');
    if (nl)
        *nl = '\0';
    if (started)
        snprintf(buf, n, "%s; under mpirun: rank %d of %d", lib, world_rank, world_size);
    else
        snprintf(buf, n, "%s linked; not under mpirun: MPI not initialised", lib);
}
