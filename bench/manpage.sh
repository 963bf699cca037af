#!/usr/bin/env bash
# Writes radpt.1 (roff) from `radpt help`, so the man page and --help are
# one text: bench/manpage.sh RADPT VERSION > radpt.1
set -euo pipefail
radpt=$1
version=$2
cat <<HEAD
.TH RADPT 1 "" "radpt $version" "User Commands"
.SH NAME
radpt \\- finite-element radiosity and Monte Carlo path tracing on the same diffuse scenes, measured against each other
.SH SYNOPSIS
.B radpt
.I COMMAND
[\\fIOPTIONS\\fR]
.br
.B mpirun
.B \\-np
.I K
.B radpt
.I COMMAND
[\\fIOPTIONS\\fR]
.SH DESCRIPTION
The text below is the one \\fBradpt help\\fR prints.
.PP
.nf
HEAD
# roff: a backslash is \e; a line may not start with . or '
"$radpt" help | sed -e 's/\\/\\e/g' -e "s/^\\([.']\\)/\\\\\\&\\1/"
cat <<'TAIL'
.fi
.SH PLUGINS
Every command takes \fB\-\-plugin\fR \fIPATH.so\fR (repeatable), and loads the
plugins that \fBRADPT_PLUGIN_PATH\fR names (files and directories, separated by
colons): shared objects that add methods through \fI<radpt/solvers/plugin.h>\fR.
Build one with \fBpkg-config \-\-cflags \-\-libs radpt\fR.
.SH SEE ALSO
.BR mpirun (1),
.BR pkg-config (1)
TAIL
