/* bench/run/journal.c: a study's records survive a reopen bit for bit,
 * a record cut short is dropped, and a journal of another study is
 * refused on resume. */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bench/run/journal.h"

static void tmpdir(char *dir, size_t n)
{
    snprintf(dir, n, "/tmp/rp-journal-XXXXXX");
    cr_assert_not_null(mkdtemp(dir));
}

Test(journal, records_read_back_bit_identical)
{
    char dir[64];
    tmpdir(dir, sizeof dir);
    rp_journal *j;
    rp_error err;
    cr_assert_eq(rp_journal_open(dir, "experiment x --quick", 0, &j, &err), RP_OK);
    /* values whose shortest decimal form is not their %.6g form */
    double v[5] = {0.1, 1.0 / 3.0, 6.02214076e23, -0.0, NAN};
    cr_assert_eq(rp_journal_put_doubles(j, "pathtrace seed 1", v, 5, &err), RP_OK);
    cr_assert_eq(rp_journal_put(j, "note", "text with spaces", &err), RP_OK);
    rp_journal_close(j);

    cr_assert_eq(rp_journal_open(dir, "experiment x --quick", 1, &j, &err), RP_OK, "%s", err.message);
    cr_assert_eq(rp_journal_resumed(j), 2);
    double w[5];
    cr_assert_eq(rp_journal_get_doubles(j, "pathtrace seed 1", w, 5), 1);
    for (int i = 0; i < 4; i++)
        cr_assert(memcmp(&v[i], &w[i], sizeof v[i]) == 0, "value %d: %.17g read back as %.17g", i, v[i], w[i]);
    cr_assert(isnan(w[4]));
    cr_assert_eq(rp_journal_get_doubles(j, "pathtrace seed 1", w, 4), 0, "a count mismatch is not a match");
    cr_assert_str_eq(rp_journal_get(j, "note"), "text with spaces");
    cr_assert_null(rp_journal_get(j, "absent"));
    rp_journal_close(j);

    /* another study's journal is refused, naming both */
    cr_assert_eq(rp_journal_open(dir, "experiment y", 1, &j, &err), RP_ERR_INPUT);
    cr_assert(strstr(err.message, "experiment x --quick") && strstr(err.message, "experiment y"), "%s",
              err.message);
    char path[128];
    snprintf(path, sizeof path, "%s/journal.txt", dir);
    unlink(path);
    rmdir(dir);
}

Test(journal, torn_record_is_dropped)
{
    char dir[64], path[128];
    tmpdir(dir, sizeof dir);
    snprintf(path, sizeof path, "%s/journal.txt", dir);
    FILE *f = fopen(path, "w");
    cr_assert_not_null(f);
    fputs("radpt-journal 1\nidentity s\nrun a\t1 2\nrun b\t3 4", f); /* b: no newline */
    fclose(f);
    rp_journal *j;
    rp_error err;
    cr_assert_eq(rp_journal_open(dir, "s", 1, &j, &err), RP_OK, "%s", err.message);
    cr_assert_eq(rp_journal_resumed(j), 1);
    cr_assert_null(rp_journal_get(j, "run b"));
    cr_assert_eq(rp_journal_put(j, "run b", "5 6", &err), RP_OK);
    rp_journal_close(j);
    cr_assert_eq(rp_journal_open(dir, "s", 1, &j, &err), RP_OK, "%s", err.message);
    cr_assert_eq(rp_journal_resumed(j), 2);
    cr_assert_str_eq(rp_journal_get(j, "run b"), "5 6");
    rp_journal_close(j);
    /* no journal at all: resume is an input error naming the file */
    unlink(path);
    cr_assert_eq(rp_journal_open(dir, "s", 1, &j, &err), RP_ERR_INPUT);
    cr_assert(strstr(err.message, "journal.txt"), "%s", err.message);
    rmdir(dir);
}

/* What a rank other than 0 recorded in its side journal before mpirun
 * killed it is read back on resume after the journal; a side journal of
 * another study is skipped; a study that ended removes them. */
Test(journal, side_journals_of_ranks_are_read_back)
{
    char dir[64], path[128];
    tmpdir(dir, sizeof dir);
    rp_journal *j;
    rp_error err;
    cr_assert_eq(rp_journal_open(dir, "bench s", 0, &j, &err), RP_OK);
    cr_assert_eq(rp_journal_put(j, "run 1", "1", &err), RP_OK);
    rp_journal_close(j);
    /* as ranks 1 and 2 write theirs (journal.h); rank 2's is another study */
    static const char *side[2][2] = {{"journal.rank-1.txt", "radpt-journal 1\nidentity bench s\nrun 2\t2\nrun 3\t3\nrun 4\t4"},
                                     {"journal.rank-2.txt", "radpt-journal 1\nidentity bench t\nrun 5\t5\n"}};
    for (int r = 0; r < 2; r++) {
        snprintf(path, sizeof path, "%s/%s", dir, side[r][0]);
        FILE *f = fopen(path, "w");
        cr_assert_not_null(f);
        fputs(side[r][1], f); /* rank 1's last record cut short by the kill */
        fclose(f);
    }
    cr_assert_eq(rp_journal_open(dir, "bench s", 1, &j, &err), RP_OK, "%s", err.message);
    cr_expect_eq(rp_journal_resumed(j), 3);
    cr_expect_str_eq(rp_journal_get(j, "run 3"), "3");
    cr_expect_null(rp_journal_get(j, "run 4"));
    cr_expect_null(rp_journal_get(j, "run 5"));
    rp_journal_tidy(j);
    rp_journal_close(j);
    snprintf(path, sizeof path, "%s/journal.rank-1.txt", dir);
    cr_expect_eq(access(path, F_OK), -1, "tidy leaves %s", path);
    /* journal.txt now holds rank 1's records itself */
    cr_assert_eq(rp_journal_open(dir, "bench s", 1, &j, &err), RP_OK, "%s", err.message);
    cr_expect_eq(rp_journal_resumed(j), 3);
    rp_journal_close(j);
    char cmd[160];
    snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
    cr_expect_eq(system(cmd), 0);
}
