/* Open MPI as a layer under the command line (docs/design.md, "MPI as a
 * layer"): the only file of radpt that includes mpi.h.
 *
 * One binary.  Started by mpirun (Open MPI sets OMPI_COMM_WORLD_SIZE in
 * each process it launches) radpt initialises MPI and runs as one rank of
 * MPI_COMM_WORLD; started plainly it makes no MPI call at all (a singleton
 * MPI_Init costs ~0.4 s).
 *
 * Rank 0 owns the terminal and the files: the other ranks' standard output
 * goes to /dev/null and their standard error to a private temporary file,
 * which is shown only when that rank is the one whose error ends the run
 * (rp_mpi_finish). */
#ifndef RP_MPI_H
#define RP_MPI_H

#include <stddef.h>

#include "solvers/comm.h"

/* Initialises MPI when launched by mpirun; a no-op otherwise.  Returns 0,
 * or 1 (after a message) when MPI could not start. */
int rp_mpi_start(int *argc, char ***argv);

/* MPI_COMM_WORLD as an rp_comm, or NULL in a plain process (and under
 * mpirun -np 1, where one rank is a plain process). */
const rp_comm *rp_mpi_world(void);

/* This process's rank (0 in a plain process) and the rank count (1). */
int rp_mpi_rank(void);
int rp_mpi_size(void);

/* Ends MPI (a no-op in a plain process) and returns the exit status all
 * ranks share: every rank hands in its own; the lowest rank that failed
 * decides, and when that is not rank 0 its saved standard error is copied
 * to the real one, so the user sees the one message a single process
 * would print (input errors happen alike on every rank, and rank 0 has
 * printed them).  Waits without spinning, so ranks idle while rank 0
 * works alone cost no CPU. */
int rp_mpi_finish(int code);

/* "Open MPI v4.1.4; under mpirun: rank 0 of 2", or "... linked; not under
 * mpirun: MPI not initialised" (radpt --version). */
void rp_mpi_describe(char *buf, size_t n);

#endif
