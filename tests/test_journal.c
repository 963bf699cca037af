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
