/* The radpt subcommands; each returns the process exit status. */
#ifndef RP_COMMANDS_H
#define RP_COMMANDS_H

#include <stdio.h>

int rp_cmd_info(int argc, char **argv);
int rp_cmd_render(int argc, char **argv);
int rp_cmd_probe(int argc, char **argv);
int rp_cmd_formfactor(int argc, char **argv);
int rp_cmd_throughput(int argc, char **argv);
int rp_cmd_samplers(int argc, char **argv);
int rp_cmd_reference(int argc, char **argv);
int rp_cmd_bench(int argc, char **argv);
int rp_cmd_experiment(int argc, char **argv);
int rp_cmd_compare(int argc, char **argv);

/* radpt help compare: what compare reads, which pixels count, its output. */
void rp_cmd_compare_help(FILE *f);

#endif
