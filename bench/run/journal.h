/* A study's journal: each finished unit of work (one run of a method with
 * one seed, one row of an experiment's table) is recorded on disk the
 * moment it finishes, so that an interrupted study loses nothing and
 * `--resume DIR` skips what is done.
 *
 * DIR/journal.txt is text.  Its head is
 *
 *     radpt-journal 1
 *     identity <one line: what the study is (command, scene hashes, options)>
 *
 * and then one line per finished unit, "<key>\t<payload>\n".  A record is
 * appended with one write(2) and fsync(2)ed: after a crash or a signal a
 * record is whole or absent (a last line without its '\n' is ignored when
 * the journal is read back).  Numbers in payloads are written with %.17g
 * (rp_journal_put_doubles), which reads back bit-identical, so a resumed
 * study's results equal an uninterrupted one's, timings aside.
 *
 * A key is the unit's name within the study ("pathtrace:spp=16 seed 2",
 * "rho=0.9 southwell"); it must not contain a tab or a newline.  A payload
 * must not contain a newline. */
#ifndef RP_JOURNAL_H
#define RP_JOURNAL_H

#include <stddef.h>

#include "geometry/status.h"

typedef struct rp_journal rp_journal;

/* Under mpirun, rank 0 appends to DIR/journal.txt and every other rank R
 * to its side journal DIR/journal.rank-R.txt (same format), each the
 * moment a unit finishes there: mpirun kills the ranks a second after
 * Ctrl-C, which may be before they hand their records to rank 0.  A resume
 * reads the side journals after the journal.
 *
 * Opens DIR/journal.txt (DIR must exist).  resume 0: a new journal (one
 * already there is replaced).  resume 1: the journal must exist and name
 * the same identity (RP_ERR_INPUT naming the file and both identities
 * otherwise); its records are loaded.  identity must be one line. */
rp_status rp_journal_open(const char *dir, const char *identity, int resume, rp_journal **out, rp_error *err);
void rp_journal_close(rp_journal *j); /* accepts NULL */

/* The payload recorded for key, or NULL (j may be NULL: no journal). */
const char *rp_journal_get(const rp_journal *j, const char *key);
/* Appends a record and syncs it to disk; a key recorded twice keeps the
 * later payload.  j NULL: nothing (RP_OK). */
rp_status rp_journal_put(rp_journal *j, const char *key, const char *payload, rp_error *err);

/* n numbers as a payload ("%.17g" each, space-separated; NaN as "nan"). */
rp_status rp_journal_put_doubles(rp_journal *j, const char *key, const double *v, size_t n, rp_error *err);
/* Reads back exactly n numbers recorded for key: 1 when found (v filled),
 * 0 when key is not recorded or holds another count of numbers (v may
 * then be partly written). */
int rp_journal_get_doubles(const rp_journal *j, const char *key, double *v, size_t n);

/* Units recorded so far (loaded and put), and those loaded by open. */
size_t rp_journal_count(const rp_journal *j);
size_t rp_journal_resumed(const rp_journal *j);
/* After a study that ended normally (every record reached rank 0's
 * journal): removes the side journals (rank 0 or a plain process). */
void rp_journal_tidy(rp_journal *j);
/* Record i (0 <= i < rp_journal_count(j), in the order loaded and put):
 * its key and payload, valid until the next put or close.  A key recorded
 * twice appears twice (rp_journal_get gives the later). */
void rp_journal_record(const rp_journal *j, size_t i, const char **key, const char **payload);
/* DIR/journal.txt, for messages. */
const char *rp_journal_path(const rp_journal *j);

#endif
