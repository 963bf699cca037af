# radpt: finite-element radiosity and Monte Carlo path tracing, compared.
#
#   make          build ./radpt
#   make deps     install the Debian packages radpt needs (only when missing)
#   make test     build and run every test (Criterion)
#   make check T=NAME   one test suite (or T=suite/test), without make deps
#   make format   clang-format the sources (.clang-format)
#   make asan     the same tests under AddressSanitizer + UBSan
#   make demo     render the built-in Cornell box
#   make bench    throughput benchmarks on the Cornell box
#   make bench-mpi  speedup and memory per rank under Open MPI (K = 1, 2)
#   make install [PREFIX=/usr/local] [DESTDIR=]   radpt, libradpt.so/.a,
#                 include/radpt/, radpt.pc, radpt.1; make uninstall removes them
#   make valgrind the demo's commands, cut down, under valgrind memcheck

DEB_PACKAGES := gcc g++ make pkg-config libgsl-dev libopenexr-dev openexr \
                libembree-dev libcgal-dev libcgal-demo libgmp-dev libmpfr-dev libcriterion-dev \
                libpng-dev gnuplot-nox openmpi-bin libopenmpi-dev libeigen3-dev

VERSION := 0.15.0
GIT_DESCRIBE := $(shell git describe --always --dirty 2>/dev/null || echo unknown)

CC  ?= gcc
CXX ?= g++
BUILD ?= build

GSL_CFLAGS := $(shell pkg-config --cflags gsl 2>/dev/null)
GSL_LIBS   := $(shell pkg-config --libs gsl 2>/dev/null || echo -lgsl -lgslcblas)

# Open MPI: only bench/run/mpi.c includes mpi.h; a plain run makes no MPI call.
MPI_CFLAGS := $(shell pkg-config --cflags ompi-c 2>/dev/null)
MPI_LIBS   := $(shell pkg-config --libs ompi-c 2>/dev/null || echo -lmpi)
# Eigen (header-only) for CGAL's Garland-Heckbert simplification policies.
EIGEN_CFLAGS := $(shell pkg-config --cflags eigen3 2>/dev/null || echo -I/usr/include/eigen3)

OPT      ?= -O2
SANITIZE ?=
CPPFLAGS := -I. $(GSL_CFLAGS) -D_POSIX_C_SOURCE=200809L -D_DEFAULT_SOURCE
# -fPIC: the same objects go into libradpt.a and libradpt.so (which the
# radpt binary and plugins share); no semantic interposition, so calls
# inside the library stay direct.
PIC      := -fPIC -fno-semantic-interposition
CFLAGS   := -std=c11 $(OPT) -g -Wall -Wextra -Werror -fopenmp -MMD -MP $(PIC) $(SANITIZE)
# CGAL is heavy to compile: no -g, one or two translation units.  NDEBUG
# compiles CGAL's and Eigen's internal checks (CGAL_assertion, eigen_assert)
# out of the plain build: the bunny's simplification takes 0.9 s instead of
# 1.6 s, with the same mesh.  The sanitizer build (make asan) keeps them, so
# the tests still run under them.
CXXFLAGS := -std=c++17 $(OPT) -Wall -Wextra -Werror -MMD -MP -DCGAL_DISABLE_GMPXX $(if $(SANITIZE),,-DNDEBUG) \
            $(PIC) $(SANITIZE)
LDLIBS   := -lembree3 -lOpenEXRCore-3_1 -lpng $(GSL_LIBS) $(MPI_LIBS) \
            -lgmp -lmpfr -lstdc++ -lm
LDFLAGS  := -fopenmp $(SANITIZE)

# libradpt.a: scenes and geometry, the solvers, and the measuring harness
# (bench/run: driver, references, metrics; bench/report: files, charts,
# images; bench/experiments).  The command line (bench/cli) is not in it.
LIB_C   := $(wildcard geometry/*.c solvers/*.c solvers/*/*.c) \
           $(wildcard bench/run/*.c bench/report/*.c bench/experiments/*.c)
CLI_C   := $(wildcard bench/cli/*.c)
CLI_OBJ := $(CLI_C:%.c=$(BUILD)/%.o)
LIB_CXX := $(wildcard geometry/cgal/*.cpp)
LIB_OBJ := $(LIB_C:%.c=$(BUILD)/%.o) $(LIB_CXX:%.cpp=$(BUILD)/%.o)
TEST_C  := $(wildcard tests/*.c)
TEST_OBJ := $(TEST_C:%.c=$(BUILD)/%.o)

# Scanned meshes come from CGAL's data set, which Debian's libcgal-demo
# installs under libcgal-dev's doc directory; extracted at build time
# rather than committed.
CGAL_DATA := /usr/share/doc/libcgal-dev/data.tar.gz
MESHES := scenes/data/bunny00.off scenes/data/elephant.off scenes/data/armadillo.off

.PHONY: all deps test check asan demo bench bench-mpi install uninstall plugins clean FORCE meshes fuzz fuzz-deps valgrind format
all: radpt meshes

radpt: $(BUILD)/radpt
	cp $< $@

# The radpt binary links libradpt.so, found beside it ($$ORIGIN: build/,
# build-asan/) or under build/ (the copy ./radpt); the installed one is
# relinked to find it in ../lib (make install).  Plugins resolve radpt's
# functions against that same loaded library.
SONAME  := libradpt.so.0
SOREAL  := libradpt.so.$(VERSION)
$(BUILD)/radpt: $(CLI_OBJ) $(BUILD)/$(SOREAL)
	$(CC) $(LDFLAGS) -o $@ $(CLI_OBJ) -L$(BUILD) -lradpt -Wl,-rpath,'$$ORIGIN:$$ORIGIN/$(BUILD)' $(LDLIBS)

$(BUILD)/libradpt.a: $(LIB_OBJ)
	rm -f $@
	ar rcs $@ $^

$(BUILD)/$(SOREAL): $(LIB_OBJ)
	$(CC) $(LDFLAGS) -shared -Wl,-soname,$(SONAME) -Wl,-Bsymbolic-functions -o $@ $^ $(LDLIBS)
	ln -sf $(SOREAL) $(BUILD)/$(SONAME)
	ln -sf $(SONAME) $(BUILD)/libradpt.so

# Objects depend on the compiler flags too (a build directory made before
# a flag changed, such as -fPIC, is rebuilt rather than linked stale).
# (FLAGS_TEXT is expanded here, once: target-specific additions such as
# main.o's version string must not reach the stamp.)
FLAGS_STAMP := $(BUILD)/flags.txt
FLAGS_TEXT := $(CC) $(CXX) $(CPPFLAGS) $(CFLAGS) $(CXXFLAGS)
$(FLAGS_STAMP): FORCE
	@mkdir -p $(BUILD)
	@echo '$(FLAGS_TEXT)' | cmp -s - $@ || echo '$(FLAGS_TEXT)' > $@
FORCE:

$(BUILD)/%.o: %.c $(FLAGS_STAMP)
	@mkdir -p $(dir $@)
	$(CC) $(CPPFLAGS) $(CFLAGS) -c -o $@ $<

$(BUILD)/%.o: %.cpp $(FLAGS_STAMP)
	@mkdir -p $(dir $@)
	$(CXX) $(CPPFLAGS) $(CXXFLAGS) -c -o $@ $<

$(BUILD)/tests/run: $(TEST_OBJ) $(BUILD)/libradpt.a
	$(CC) $(LDFLAGS) -o $@ $^ -lcriterion $(LDLIBS)

$(BUILD)/bench/run/mpi.o: CPPFLAGS += $(MPI_CFLAGS)
$(BUILD)/geometry/cgal/simplify.o $(FUZZ_BUILD)/geometry/cgal/simplify.o: CPPFLAGS += $(EIGEN_CFLAGS) -DCGAL_EIGEN3_ENABLED
# GCC 12 takes Eigen 3.4's 4x4 matrix copy in CGAL's quadric property map for a
# use of uninitialised memory (a known false positive of -Wmaybe-uninitialized).
# Its closest-point queries run on OpenMP threads (the fuzz build, without
# -fopenmp, runs them serially).
$(BUILD)/geometry/cgal/simplify.o: CXXFLAGS += -Wno-maybe-uninitialized -fopenmp
$(BUILD)/bench/run/plugin.o: CPPFLAGS += -DRP_VERSION='"$(VERSION)"'
$(BUILD)/bench/cli/main.o: CPPFLAGS += -DRP_VERSION='"$(VERSION)"' -DRP_GIT_DESCRIBE='"$(GIT_DESCRIBE)"'
$(BUILD)/tests/%.o: CPPFLAGS += -DRP_SOURCE_DIR='"$(CURDIR)"' -DRP_BIN='"$(CURDIR)/$(BUILD)/radpt"' \
    -DRP_BUILD_DIR='"$(CURDIR)/$(BUILD)"' -DRP_BUILD_OPT='"$(OPT)"' -DRP_BUILD_SANITIZE='"$(SANITIZE)"'

meshes: $(MESHES)
scenes/data/%.off:
	@mkdir -p scenes/data
	tar -xzf $(CGAL_DATA) -O data/meshes/$*.off > $@.tmp && mv $@.tmp $@

# `test` and `demo` first install what is missing, then build in a fresh
# make (so pkg-config sees the newly installed packages).
test: deps
	@$(MAKE) --no-print-directory check

# Criterion runs each test in its own process; two workers for two cores.
# `make check T=suite` runs one suite, `make check T=suite/test` one test.
# Each worker's tests run two OpenMP threads, so the cores are shared, and
# libgomp's idle threads spin between parallel regions (GOMP_SPINCOUNT),
# taking the core the other worker needs: waiting passively, the plain suite
# took 120 s instead of 194 s, and under ASan + UBSan 219 s instead of 303 s
# (that one also before the Cornell-box quick experiments' halved budgets,
# about 10 s of it).  On cores of its own radpt runs as fast either way
# (Cornell box probe 2.07-2.14 s spinning, 2.15-2.16 s passive; the path
# tracer 2.58 M paths/s both), and libgomp reads the policy before main, so
# radpt keeps libgomp's default and only the tests set it.
T ?=
check: $(BUILD)/tests/run $(BUILD)/radpt meshes plugins
	OMP_WAIT_POLICY=passive $(BUILD)/tests/run --jobs 2 $(if $(T),--filter '$(if $(findstring /,$(T)),$(T),$(T)/*)')

# clang-format on every C, C++ and header file (style: .clang-format).
format:
	clang-format -i $$(git ls-files '*.c' '*.h' '*.cpp')

# Criterion's runner itself leaks a few bytes at exit: suppressed by name.
asan: deps
	@LSAN_OPTIONS=suppressions=$(CURDIR)/tests/lsan.supp:print_suppressions=0 \
	$(MAKE) --no-print-directory BUILD=build-asan OPT=-O1 \
	    SANITIZE="-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined" check

deps:
	@missing=""; for p in $(DEB_PACKAGES); do \
	    dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	    echo "installing:$$missing"; \
	    SUDO=; [ "$$(id -u)" -eq 0 ] || SUDO=sudo; \
	    $$SUDO apt-get update -qq && \
	    DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $$missing; \
	else echo "all Debian packages present"; fi

demo: deps
	@$(MAKE) --no-print-directory radpt meshes
	./radpt info scenes/cornell.scene
	./radpt experiment cornell -o out/cornell
	@echo "report: out/cornell/report.md"

# Performance: the path tracer against the random-ray limit on the Cornell
# box at 256 x 256, then the samplers at equal time.
bench: deps
	@$(MAKE) --no-print-directory radpt meshes
	./radpt throughput scenes/cornell.scene --spp 64
	./radpt samplers scenes/cornell.scene --spp 64 --seeds 3 --reference-spp 1024
	mkdir -p out
	./radpt bench scenes/cornell.scene --methods hierarchical:bf-epsilon=0.05:min-area=1e-4 \
		--budget 0.46 --checkpoints 2 --seeds 1 -o out/bench-hierarchical

# Strong scaling under Open MPI: K = 1 and 2 ranks, one thread each, on the
# Cornell reference render and a uniform Gauss-Seidel of ELEMENTS elements
# (bench/mpi.sh prints speedups, memory per rank and agreement).
bench-mpi: deps
	@$(MAKE) --no-print-directory radpt meshes
	bench/mpi.sh

# ------------------------------------------------------------ install
# What is installed (and all that uninstall removes): bin/radpt (relinked
# to find lib/libradpt.so.0 as $$ORIGIN/../lib), lib/libradpt.so.VERSION with
# its soname and dev links, lib/libradpt.a, the public headers under
# include/radpt/ (include/radpt/radpt.h and the geometry/ and solvers/
# headers it includes), lib/pkgconfig/radpt.pc, share/man/man1/radpt.1.
PREFIX  ?= /usr/local
DESTDIR ?=
LIBDIR  := $(PREFIX)/lib
INCDIR  := $(PREFIX)/include/radpt
PUBLIC_GEOMETRY := vec.h status.h scene.h mesh.h raycast.h sample.h camera.h
PUBLIC_SOLVERS  := comm.h solver.h plugin.h
INSTALLED := $(PREFIX)/bin/radpt $(LIBDIR)/$(SOREAL) $(LIBDIR)/$(SONAME) $(LIBDIR)/libradpt.so \
             $(LIBDIR)/libradpt.a $(LIBDIR)/pkgconfig/radpt.pc $(PREFIX)/share/man/man1/radpt.1 \
             $(INCDIR)/radpt.h $(PUBLIC_GEOMETRY:%=$(INCDIR)/geometry/%) $(PUBLIC_SOLVERS:%=$(INCDIR)/solvers/%)

$(BUILD)/radpt-installed: $(CLI_OBJ) $(BUILD)/$(SOREAL)
	$(CC) $(LDFLAGS) -o $@ $(CLI_OBJ) -L$(BUILD) -lradpt -Wl,-rpath,'$$ORIGIN/../lib' $(LDLIBS)

# radpt.pc is relocatable: its prefix is found from where the .pc file is
# (${pcfiledir}, pkg-config and pkgconf both know it), so a DESTDIR or
# moved install works with PKG_CONFIG_PATH alone (a fixed prefix=/usr
# would even be dropped as a system directory and hide the staged headers).
PC_LINES := 'prefix=$${pcfiledir}/../..' 'libdir=$${prefix}/lib' 'includedir=$${prefix}/include' '' 'Name: radpt' \
    'Description: radiosity and path tracing compared: the solver interface, scene and ray queries, plugins' \
    'Version: $(VERSION)' 'Cflags: -I$${includedir}' 'Libs: -L$${libdir} -lradpt -lm' 'Libs.private: $(LDLIBS)'

$(BUILD)/radpt.1: $(BUILD)/radpt bench/manpage.sh
	bench/manpage.sh $(BUILD)/radpt $(VERSION) > $@

install: $(BUILD)/radpt-installed $(BUILD)/$(SOREAL) $(BUILD)/libradpt.a $(BUILD)/radpt.1
	install -d $(DESTDIR)$(PREFIX)/bin $(DESTDIR)$(LIBDIR)/pkgconfig $(DESTDIR)$(PREFIX)/share/man/man1 \
	    $(DESTDIR)$(INCDIR)/geometry $(DESTDIR)$(INCDIR)/solvers
	install -m 755 $(BUILD)/radpt-installed $(DESTDIR)$(PREFIX)/bin/radpt
	install -m 755 $(BUILD)/$(SOREAL) $(DESTDIR)$(LIBDIR)/$(SOREAL)
	ln -sf $(SOREAL) $(DESTDIR)$(LIBDIR)/$(SONAME)
	ln -sf $(SONAME) $(DESTDIR)$(LIBDIR)/libradpt.so
	install -m 644 $(BUILD)/libradpt.a $(DESTDIR)$(LIBDIR)/libradpt.a
	printf '%s\n' $(PC_LINES) > $(DESTDIR)$(LIBDIR)/pkgconfig/radpt.pc
	chmod 644 $(DESTDIR)$(LIBDIR)/pkgconfig/radpt.pc
	install -m 644 $(BUILD)/radpt.1 $(DESTDIR)$(PREFIX)/share/man/man1/radpt.1
	install -m 644 include/radpt/radpt.h $(DESTDIR)$(INCDIR)/radpt.h
	install -m 644 $(PUBLIC_GEOMETRY:%=geometry/%) $(DESTDIR)$(INCDIR)/geometry/
	install -m 644 $(PUBLIC_SOLVERS:%=solvers/%) $(DESTDIR)$(INCDIR)/solvers/

uninstall:
	rm -f $(INSTALLED:%=$(DESTDIR)%)
	-rmdir $(DESTDIR)$(INCDIR)/geometry $(DESTDIR)$(INCDIR)/solvers $(DESTDIR)$(INCDIR) 2>/dev/null
	-rmdir -p $(DESTDIR)$(LIBDIR)/pkgconfig $(DESTDIR)$(PREFIX)/share/man/man1 $(DESTDIR)$(PREFIX)/bin \
	    $(DESTDIR)$(PREFIX)/include 2>/dev/null

# The example plugins, built as a user builds them: against a DESTDIR
# install (in $(BUILD)/stage) through pkg-config only; the tests load them
# from $(BUILD)/plugins/ (tests/test_plugin.c).
STAGE := $(CURDIR)/$(BUILD)/stage
EXAMPLES := $(notdir $(wildcard examples/plugins/*))
# (everything install needs is a prerequisite, so that under -j the
# sub-make finds it built rather than racing this make to build it)
plugins: $(BUILD)/radpt-installed $(BUILD)/$(SOREAL) $(BUILD)/libradpt.a $(BUILD)/radpt.1
	@$(MAKE) --no-print-directory install DESTDIR=$(STAGE) PREFIX=/usr >/dev/null
	@mkdir -p $(BUILD)/plugins
	@for e in $(EXAMPLES); do \
	    PKG_CONFIG_LIBDIR=$(STAGE)/usr/lib/pkgconfig \
	    $(MAKE) --no-print-directory -C examples/plugins/$$e OUT=$(CURDIR)/$(BUILD)/plugins || exit 1; done

# Fuzzing with libFuzzer (clang): the scene parser and mesh import, each
# for FUZZ_SECONDS; new corpus entries land in tests/fuzz/<target>/.
FUZZ_SECONDS ?= 600
FUZZ_BUILD := build-fuzz
FUZZ_FLAGS := -g -O1 -fsanitize=fuzzer-no-link,address,undefined -fno-sanitize-recover=undefined
FUZZ_LIB_OBJ := $(patsubst %.c,$(FUZZ_BUILD)/%.o,$(wildcard geometry/*.c)) $(LIB_CXX:%.cpp=$(FUZZ_BUILD)/%.o)

fuzz-deps:
	@dpkg -s clang libclang-rt-14-dev >/dev/null 2>&1 || { \
	    SUDO=; [ "$$(id -u)" -eq 0 ] || SUDO=sudo; \
	    $$SUDO apt-get update -qq && \
	    DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends clang libclang-rt-14-dev; }

fuzz: deps fuzz-deps
	@$(MAKE) --no-print-directory $(FUZZ_BUILD)/fuzz_scene $(FUZZ_BUILD)/fuzz_mesh
	@mkdir -p tests/fuzz/scene tests/fuzz/mesh
	$(FUZZ_BUILD)/fuzz_scene -max_total_time=$(FUZZ_SECONDS) -max_len=4096 \
	    tests/fuzz/scene scenes tests/bad tests/data
	$(FUZZ_BUILD)/fuzz_mesh -max_total_time=$(FUZZ_SECONDS) -max_len=4096 tests/fuzz/mesh

$(FUZZ_BUILD)/%.o: %.c
	@mkdir -p $(dir $@)
	clang $(CPPFLAGS) -std=c11 -Wall -Wextra $(FUZZ_FLAGS) -c -o $@ $<

$(FUZZ_BUILD)/%.o: %.cpp
	@mkdir -p $(dir $@)
	clang++ $(CPPFLAGS) -std=c++17 -O1 -DCGAL_DISABLE_GMPXX -fsanitize=fuzzer-no-link,address,undefined -c -o $@ $<

# Linked by clang++: UBSan's C++ runtime (vptr checks in the CGAL shim).
$(FUZZ_BUILD)/fuzz_%: $(FUZZ_BUILD)/tests/fuzz/fuzz_%.o $(FUZZ_LIB_OBJ)
	clang++ -fsanitize=fuzzer,address,undefined -o $@ $^ $(LDLIBS)

.SECONDARY: $(FUZZ_LIB_OBJ)

# Memory errors and leaks (valgrind memcheck) on the demo's commands, cut to
# sizes valgrind finishes in several minutes (7 on two busy cores); not part
# of `make test`.
# The quick Cornell experiment reads its 256 spp reference from VG_BUILD/refs,
# rendered once without valgrind (valgrind would take an hour); the other
# methods and the checkpoint/resume path run as small renders.  Valgrind
# cannot emulate the FPU rounding modes CGAL checks for at start-up, hence
# CGAL_DISABLE_ROUNDING_MATH_CHECK in this build only.
VG_BUILD := build-valgrind
VG_OUT := $(VG_BUILD)/out
VALGRIND := valgrind --error-exitcode=3 --leak-check=full --show-leak-kinds=definite --errors-for-leak-kinds=definite
VG_RADPT := $(VALGRIND) $(VG_BUILD)/radpt
valgrind: deps
	@dpkg -s valgrind >/dev/null 2>&1 || { \
	    SUDO=; [ "$$(id -u)" -eq 0 ] || SUDO=sudo; \
	    $$SUDO apt-get update -qq && \
	    DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends valgrind; }
	@$(MAKE) --no-print-directory BUILD=$(VG_BUILD) OPT="-O1 -DCGAL_DISABLE_ROUNDING_MATH_CHECK" $(VG_BUILD)/radpt meshes
	rm -rf $(VG_OUT) && mkdir -p $(VG_OUT)
	$(VG_BUILD)/radpt reference scenes/cornell.scene --spp 256 --cache $(VG_BUILD)/refs >/dev/null
	@start=$$(date +%s); set -e; \
	echo "valgrind: info, experiment cornell --quick --seeds 1"; \
	$(VG_RADPT) info scenes/cornell.scene >/dev/null; \
	$(VG_RADPT) experiment cornell --quick --seeds 1 --cache $(VG_BUILD)/refs -o $(VG_OUT)/cornell >/dev/null; \
	echo "valgrind: every other method, small renders"; \
	for m in "jacobi --elements 150" "gauss-seidel --elements 150 --reconstruct gouraud" "direct --elements 150" \
	         "stochastic-jacobi --elements 150 --rays 20000 --batches 4" \
	         "hierarchical --bf-epsilon 0.05 --min-area 1e-3 --vis-rays 4"; do \
	    $(VG_RADPT) render scenes/cornell.scene --method $$m --spp 1 -o $(VG_OUT)/m.exr >/dev/null; done; \
	echo "valgrind: checkpoint, resume, probe, references"; \
	$(VG_RADPT) render scenes/plates-parallel.scene --method pathtrace --spp 1 \
	    --checkpoint $(VG_OUT)/pt.ckpt -o $(VG_OUT)/pt.exr --png $(VG_OUT)/pt.png >/dev/null; \
	$(VG_RADPT) render scenes/plates-parallel.scene --method pathtrace --spp 2 \
	    --resume $(VG_OUT)/pt.ckpt -o $(VG_OUT)/pt.exr >/dev/null; \
	$(VG_RADPT) probe scenes/cornell.scene --method pathtrace --surface-averages --samples 64 --json >/dev/null; \
	$(VG_RADPT) reference scenes/plates-parallel.scene --spp 1 --cache $(VG_OUT)/refs \
	    --checkpoint $(VG_OUT)/ref.ckpt >/dev/null; \
	$(VG_RADPT) reference scenes/furnace.scene --cache $(VG_OUT)/refs >/dev/null; \
	echo "valgrind: no errors, no definite leaks ($$(( $$(date +%s) - start )) s)"

# An independent check, not part of `make test` (CI has no Blender): the
# Cornell box and the furnace rendered by Blender's Cycles
# (bench/independent/cycles.py) against radpt's references; fails when a
# channel mean differs by 1% or more.  See bench/independent/README.md.
.PHONY: independent
IND_OUT := out/independent
IND_BLENDER := blender -b --factory-startup -noaudio --python bench/independent/cycles.py --
independent: deps
	@missing=""; for p in blender python3-numpy; do \
	    dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	    echo "installing:$$missing"; \
	    SUDO=; [ "$$(id -u)" -eq 0 ] || SUDO=sudo; \
	    $$SUDO apt-get update -qq && \
	    DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $$missing; fi
	@$(MAKE) --no-print-directory radpt
	@mkdir -p $(IND_OUT)
	./radpt reference scenes/furnace.scene --json > $(IND_OUT)/furnace-reference.json
	$(IND_BLENDER) scenes/furnace.scene -o $(IND_OUT)/furnace-cycles.exr --spp 16 --seeds 4 \
	    --compare $$(sed -n 's/.*"image": "\([^"]*\)".*/\1/p' $(IND_OUT)/furnace-reference.json)
	./radpt reference scenes/cornell.scene --json > $(IND_OUT)/cornell-reference.json
	$(IND_BLENDER) scenes/cornell.scene -o $(IND_OUT)/cornell-cycles.exr --spp 256 --seeds 4 --seed 11 \
	    --compare $$(sed -n 's/.*"image": "\([^"]*\)".*/\1/p' $(IND_OUT)/cornell-reference.json)

clean:
	rm -rf build build-asan build-fuzz build-valgrind radpt scenes/data

-include $(LIB_OBJ:.o=.d) $(TEST_OBJ:.o=.d) $(CLI_OBJ:.o=.d)
