/* The communicator a solver sees when its work is split across processes
 * (docs/design.md, "MPI as a layer").
 *
 * Solvers make no MPI call: a distributed run hands them an rp_comm whose
 * operations bench/run/mpi.c implements on MPI_COMM_WORLD; a plain process
 * hands them NULL, which the inline helpers below treat as one rank (every
 * operation a no-op).  A method that splits its work says so in its type
 * table (rp_solver_type.distributed) and splits it by global index (pixel
 * tile, probe chunk, form-factor row), so that its answer is the same for
 * any rank count.
 *
 * Every operation is collective: all ranks of the communicator call it, in
 * the same order, with the same sizes. */
#ifndef RP_COMM_H
#define RP_COMM_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct rp_comm rp_comm;
struct rp_comm {
    int rank, size;
    /* buf[i] <- the sum over ranks of buf[i], on every rank.  Exact (so
     * bit-identical for any rank count) where at most one rank holds a
     * non-zero buf[i]: callers split sums that way. */
    void (*sum)(const rp_comm *c, double *buf, size_t n);
    /* buf[i] <- the maximum over ranks of buf[i], on every rank. */
    void (*max)(const rp_comm *c, double *buf, size_t n);
    /* bytes of root's buf to every rank. */
    void (*bcast)(const rp_comm *c, void *buf, size_t bytes, int root);
    void *impl;
};

static inline int rp_comm_rank(const rp_comm *c)
{
    return c ? c->rank : 0;
}

static inline int rp_comm_size(const rp_comm *c)
{
    return c ? c->size : 1;
}

static inline void rp_comm_sum(const rp_comm *c, double *buf, size_t n)
{
    if (c && c->size > 1)
        c->sum(c, buf, n);
}

static inline void rp_comm_max(const rp_comm *c, double *buf, size_t n)
{
    if (c && c->size > 1)
        c->max(c, buf, n);
}

static inline void rp_comm_bcast(const rp_comm *c, void *buf, size_t bytes, int root)
{
    if (c && c->size > 1)
        c->bcast(c, buf, bytes, root);
}

/* 1 when this rank owns work item `index` of a split by global index
 * (round robin, so neighbouring tiles or rows spread over ranks). */
static inline int rp_comm_owns(const rp_comm *c, size_t index)
{
    return !c || c->size <= 1 || (int)(index % (size_t)c->size) == c->rank;
}

#ifdef __cplusplus
}
#endif

#endif
