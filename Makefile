# clipmap — plain Makefile, out-of-tree objects in build/ (BUILD=... for variants).
#   make            build everything
#   make check      install deps, build, run every test
#   make asan/tsan  the same suite under sanitizers (build-asan/, build-tsan/)
#   make bench      benchmarks that print figures
#   make deps       install the Debian packages the project needs (and prepare data/)
#   make data       install the planet data packages and import them into data/

BUILD   ?= build
.DEFAULT_GOAL := all
CC      ?= cc
CXX     ?= g++
PKGS    := OpenImageIO geographiclib libxxhash libzstd liblz4 libsystemd gdal lmdb libmicrohttpd zlib libtiff-4 gnutls libwebp
PKG_CFLAGS := $(shell pkg-config --cflags $(PKGS) 2>/dev/null)
PKG_LIBS   := $(shell pkg-config --libs $(PKGS) 2>/dev/null)

OPT     ?= -O2 -g
WARN    := -Wall -Wextra -Wshadow -Wstrict-prototypes -Wmissing-prototypes -Wformat=2 -Wvla \
           -fno-common -Werror
CFLAGS  += -std=c11 -D_GNU_SOURCE $(OPT) $(WARN) -pthread -MMD -MP -iquote . -iquote daemon -iquote tests \
           $(SAN)
CXXFLAGS += -std=c++17 $(OPT) -Wall -Wextra -Werror -fPIC -pthread -MMD -MP -iquote . $(SAN) \
           $(filter-out -I/usr/include,$(PKG_CFLAGS))
LDFLAGS += -pthread $(SAN)
LDLIBS  += $(PKG_LIBS) -lcmocka -lstdc++ -lm
# hiredis (the fleet's Redis tier, daemon/store_redis.c): clipmapd and the tests only.
REDIS_LIBS := $(shell pkg-config --libs hiredis 2>/dev/null || echo -lhiredis)

# Per-ISA kernels: files named *_avx2.c / *_avx512.c get their -m flags (run-time dispatch).
AVX2_FLAGS   := -mavx2 -mfma -mbmi2
AVX512_FLAGS := -mavx512f -mavx512dq -mavx512bw -mavx512vl -mavx2 -mfma -mbmi2

# The wings (docs/ARCHITECTURE.md): one static library each, so a call across a forbidden edge
# fails to link. Every main() lives in its own file; everything else links into the tests.
#   common   protocol, codec, grid, config parsing, image I/O, geodesy, log   (uses nothing)
#   engine   daemon/engine/ and its nodes/: graph, cache, scheduler            (uses common)
#   server   daemon/: clipmapd's loop, sessions, control                     (engine, common)
#   client   client/: the protocol client                                    (common)
#   ctl      client/ctl/: clipmapctl                                         (client, engine, common)
#   view     client/view/: clipmapview, GL                                   (client, engine, common)
MAINS        := daemon/clipmapd.c client/ctl/clipmapctl.c client/view/clipmapview.c
COMMON_SRC   := $(wildcard common/*.c)
COMMON_CXX   := $(wildcard common/*.cpp)
ENGINE_SRC   := $(wildcard daemon/engine/*.c daemon/engine/nodes/*.c)
SERVER_SRC   := $(filter-out $(MAINS),$(wildcard daemon/*.c))
CLIENT_SRC   := $(wildcard client/*.c)
CTL_SRC      := $(filter-out $(MAINS),$(wildcard client/ctl/*.c))
VIEW_SRC     := $(filter-out $(MAINS),$(wildcard client/view/*.c))
COMMON_LIB   := $(BUILD)/libcommon.a
ENGINE_LIB   := $(BUILD)/libengine.a
SERVER_LIB   := $(BUILD)/libserver.a
CLIENT_LIB   := $(BUILD)/libclient.a
CTL_LIB      := $(BUILD)/libctl.a
VIEW_LIB     := $(BUILD)/libview.a
$(COMMON_LIB): $(COMMON_SRC:%.c=$(BUILD)/%.o) $(COMMON_CXX:%.cpp=$(BUILD)/%.o)
$(ENGINE_LIB): $(ENGINE_SRC:%.c=$(BUILD)/%.o)
$(SERVER_LIB): $(SERVER_SRC:%.c=$(BUILD)/%.o)
$(CLIENT_LIB): $(CLIENT_SRC:%.c=$(BUILD)/%.o)
$(CTL_LIB): $(CTL_SRC:%.c=$(BUILD)/%.o)
$(VIEW_LIB): $(VIEW_SRC:%.c=$(BUILD)/%.o)
# Tests may use every wing (GL ones only in the view's tests and benches).
TEST_LIBS    := $(SERVER_LIB) $(CTL_LIB) $(CLIENT_LIB) $(ENGINE_LIB) $(COMMON_LIB)

TEST_SRC     := $(wildcard tests/unit/test_*.c tests/integration/test_*.c)
UNIT_BIN     := $(patsubst %.c,$(BUILD)/tests/%,$(notdir $(TEST_SRC)))
# Test-only helpers (tests/support/) linked into every test program.
TEST_SUPPORT_OBJ := $(patsubst %.c,$(BUILD)/%.o,$(wildcard tests/support/*.c))
BENCH_SRC    := $(wildcard tests/bench/bench_*.c)
BENCH_BIN    := $(BENCH_SRC:tests/bench/%.c=$(BUILD)/tests/%)
PROGS        := $(foreach m,$(MAINS),$(if $(wildcard $(m)),$(BUILD)/$(notdir $(basename $(m)))))
PROGS        += $(BUILD)/clipmapctl-offline
# Programs that draw: they link the view wing and GL.
GL_TESTS     := $(wildcard tests/unit/test_view_*.c tests/integration/test_view_*.c) tests/bench/bench_view.c tests/bench/bench_keepup.c

# The viewer: GL code in its own library (EGL, GLFW linked; OSMesa dlopen'ed at run time), shaders
# embedded as C strings generated from shaders/, every shader checked by glslangValidator.
GL_CFLAGS    := $(shell pkg-config --cflags egl opengl glfw3 2>/dev/null)
GL_LIBS      := $(shell pkg-config --libs egl 2>/dev/null || echo -lEGL) \
                $(shell pkg-config --libs glfw3 2>/dev/null || echo -lglfw) -ldl
SHADERS      := $(wildcard shaders/*.vert shaders/*.frag)
SHADER_HDR   := $(foreach s,$(SHADERS),$(BUILD)/gen/$(subst .,_,$(notdir $(s))).h)
VIEW_OBJ     := $(VIEW_SRC:%.c=$(BUILD)/%.o)
VIEW_TESTOBJ := $(patsubst %.c,$(BUILD)/%.o,$(GL_TESTS)) $(BUILD)/client/view/clipmapview.o

# The version the programs print (--version): `git describe --always --dirty` of this checkout,
# else VERSION_FALLBACK (a release tarball), given to the three mains as CLIPMAP_VERSION.
# build/gen/version.txt is rewritten only when it changes, so only the mains recompile then.
VERSION_FALLBACK := 0.1.0
VERSION ?= $(shell git describe --always --dirty 2>/dev/null || echo $(VERSION_FALLBACK))
MAIN_OBJ     := $(MAINS:%.c=$(BUILD)/%.o) $(BUILD)/client/ctl/clipmapctl_thin.o
$(MAIN_OBJ): CFLAGS += -DCLIPMAP_VERSION='"$(VERSION)"'
$(MAIN_OBJ): $(BUILD)/gen/version.txt
$(BUILD)/gen/version.txt: FORCE
	@mkdir -p $(dir $@)
	@printf '%s\n' '$(VERSION)' > $@.tmp
	@if cmp -s $@.tmp $@; then rm -f $@.tmp; else mv $@.tmp $@; fi
FORCE:

.PHONY: all check test layers asan tsan bench bench-keepup deps clean demo data shader-check fuzz install fleet-demo FORCE
.SECONDARY:
all: $(PROGS) $(UNIT_BIN) $(BENCH_BIN)

$(BUILD)/%.o: %.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -c $< -o $@
$(BUILD)/%_avx2.o: %_avx2.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) $(AVX2_FLAGS) -c $< -o $@
$(BUILD)/%_avx512.o: %_avx512.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) $(AVX512_FLAGS) -c $< -o $@
$(BUILD)/%.o: %.cpp
	@mkdir -p $(dir $@)
	$(CXX) $(CXXFLAGS) -c $< -o $@

$(BUILD)/lib%.a:
	@rm -f $@
	ar rcs $@ $^

$(BUILD)/clipmapd: $(BUILD)/daemon/clipmapd.o $(SERVER_LIB) $(ENGINE_LIB) $(COMMON_LIB)
	$(CC) $(LDFLAGS) $^ $(LDLIBS) $(REDIS_LIBS) -o $@
# clipmapctl-offline: every command. clipmapctl: the online ones (the same main, CTL_THIN),
# without the engine, and --as-needed drops the shared libraries only the engine uses (GDAL,
# OpenImageIO: ~260 of them); it runs the offline commands through clipmapctl-offline.
$(BUILD)/clipmapctl-offline: $(BUILD)/client/ctl/clipmapctl.o $(CTL_LIB) $(CLIENT_LIB) $(ENGINE_LIB) $(COMMON_LIB)
	$(CC) $(LDFLAGS) $^ $(LDLIBS) -o $@
$(BUILD)/client/ctl/clipmapctl_thin.o: client/ctl/clipmapctl.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -DCTL_THIN -c $< -o $@
$(BUILD)/clipmapctl: $(BUILD)/client/ctl/clipmapctl_thin.o $(CTL_LIB) $(CLIENT_LIB) $(COMMON_LIB) \
		| $(BUILD)/clipmapctl-offline
	$(CC) $(LDFLAGS) -Wl,--as-needed $(filter %.o %.a,$^) $(LDLIBS) -o $@
$(VIEW_OBJ) $(VIEW_TESTOBJ): CFLAGS += $(GL_CFLAGS) -iquote $(BUILD)/gen
$(VIEW_OBJ): $(SHADER_HDR)
$(BUILD)/gen/%_vert.h: shaders/%.vert
	@mkdir -p $(dir $@)
	@{ echo 'static const char $(notdir $(basename $@))_src[] ='; \
	   sed 's/\\/\\\\/g; s/"/\\"/g; s/^/"/; s/$$/\\n"/' $<; echo ';'; } > $@
$(BUILD)/gen/%_frag.h: shaders/%.frag
	@mkdir -p $(dir $@)
	@{ echo 'static const char $(notdir $(basename $@))_src[] ='; \
	   sed 's/\\/\\\\/g; s/"/\\"/g; s/^/"/; s/$$/\\n"/' $<; echo ';'; } > $@
$(BUILD)/clipmapview: $(BUILD)/client/view/clipmapview.o $(VIEW_LIB) $(CLIENT_LIB) $(ENGINE_LIB) $(COMMON_LIB)
	$(CC) $(LDFLAGS) $^ $(LDLIBS) $(GL_LIBS) -o $@
# One link rule per test and bench program: its object, the test support, every wing (and the
# view wing and GL for the programs that draw).
define prog_rule
$(BUILD)/tests/$(basename $(notdir $(1))): $(BUILD)/$(1:.c=.o) $(TEST_SUPPORT_OBJ) \
		$(if $(filter $(1),$(GL_TESTS)),$(VIEW_LIB)) $(TEST_LIBS)
	@mkdir -p $$(dir $$@)
	$$(CC) $$(LDFLAGS) $$^ $$(LDLIBS) $$(REDIS_LIBS) $(if $(filter $(1),$(GL_TESTS)),$$(GL_LIBS)) -o $$@
endef
$(foreach t,$(TEST_SRC) $(BENCH_SRC),$(eval $(call prog_rule,$(t))))

deps:
	@sh scripts/deps.sh

# Planet data (Debian packages) imported into data/ (gitignored); deps runs it too.
data:
	@BUILD=$(BUILD) sh scripts/data.sh

check: deps
	@$(MAKE) --no-print-directory all
	@$(MAKE) --no-print-directory shader-check layers
	@CLIPMAP_BUILD_VERSION='$(VERSION)' sh tests/run.sh $(BUILD)

test: all shader-check layers
	@CLIPMAP_BUILD_VERSION='$(VERSION)' sh tests/run.sh $(BUILD)

# The wings' include rule (docs/ARCHITECTURE.md).
layers:
	@sh tests/layers.sh

shader-check:
	@for s in $(SHADERS); do glslangValidator $$s >/dev/null || { glslangValidator $$s; exit 1; }; done
	@echo "shaders: $(words $(SHADERS)) checked by glslangValidator"


asan: export ASAN_OPTIONS = detect_leaks=1:abort_on_error=0
asan: export LSAN_OPTIONS = suppressions=$(CURDIR)/tests/lsan.supp:print_suppressions=0
asan: export UBSAN_OPTIONS = print_stacktrace=1:halt_on_error=1
asan: export CLIPMAP_TEST_SLOW = 2
asan:
	@$(MAKE) --no-print-directory BUILD=build-asan OPT="-O1 -g" \
	  SAN="-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=all" test

tsan: export TSAN_OPTIONS = suppressions=$(CURDIR)/tests/tsan.supp:halt_on_error=1:second_deadlock_stack=1
# Deadlines in the GL tests scaled (tests/support/slow.h): TSan makes synthesis 5-15x slower.
tsan: export CLIPMAP_TEST_SLOW = 8
tsan: export TEST_TIMEOUT ?= 1800
tsan:
	@$(MAKE) --no-print-directory BUILD=build-tsan OPT="-O1 -g" SAN="-fsanitize=thread" test

bench: deps
	@$(MAKE) --no-print-directory all
	@sh tests/bench/run.sh $(BUILD)

# The keep-up table alone (seed 003 Table 1); KEEPUP_FULL=1 for the full matrix.
bench-keepup: all
	@$(BUILD)/tests/bench_keepup

demo: deps
	@$(MAKE) --no-print-directory all
	@sh scripts/demo.sh $(BUILD)

# A fleet on this machine: 3 clipmapd behind HAProxy, viewers flying through it, one daemon
# killed midway, a table (scripts/fleet.sh; docs/FLEET.md).
fleet-demo: deps
	@$(MAKE) --no-print-directory all
	@sh scripts/fleet.sh $(BUILD)

# libFuzzer targets (clang): each tests/fuzz/fuzz_NAME.c runs FUZZ_SECONDS on its corpus
# (fuzz_ini also reads the shipped planet files as seeds).
FUZZ_SECONDS ?= 60
FUZZ_SRC := $(wildcard tests/fuzz/fuzz_*.c)
FUZZ_LIBSRC := common/proto.c common/proto_write.c common/tilecodec.c common/tilecodec_lossy.c \
               common/unfilter_sse2.c \
               common/pixfmt.c common/grid.c common/seagrid.c \
               common/xalloc.c common/errbuf.c
FUZZ_FLAGS := -std=c11 -D_GNU_SOURCE -g -O1 -fsanitize=fuzzer,address,undefined \
              -fno-sanitize-recover=all -iquote . -iquote daemon
build-fuzz/%: tests/fuzz/%.c $(FUZZ_LIBSRC)
	@mkdir -p build-fuzz
	clang $(FUZZ_FLAGS) $^ $(shell pkg-config --libs libzstd liblz4 libxxhash libwebp) -lm -o $@
# fuzz_ini parses planet files: it links the engine and all of common, compiled with the
# fuzzer's instrumentation (not its main) into build-fuzz/obj/.
FUZZ_OBJ_FLAGS := -g -O1 -fsanitize=fuzzer-no-link,address,undefined -fno-sanitize-recover=all \
                  -pthread -iquote . -iquote daemon
FUZZ_ENGINE_OBJ := $(patsubst %.c,build-fuzz/obj/%.o,$(ENGINE_SRC) $(COMMON_SRC)) \
                   $(patsubst %.cpp,build-fuzz/obj/%.o,$(COMMON_CXX))
build-fuzz/obj/%.o: %.c
	@mkdir -p $(dir $@)
	clang -std=c11 -D_GNU_SOURCE $(FUZZ_OBJ_FLAGS) $(filter-out -I/usr/include,$(PKG_CFLAGS)) \
		$(if $(findstring _avx512,$*),$(AVX512_FLAGS),$(if $(findstring _avx2,$*),$(AVX2_FLAGS))) -c $< -o $@
build-fuzz/obj/%.o: %.cpp
	@mkdir -p $(dir $@)
	clang++ -std=c++17 $(FUZZ_OBJ_FLAGS) $(filter-out -I/usr/include,$(PKG_CFLAGS)) -c $< -o $@
build-fuzz/fuzz_ini: tests/fuzz/fuzz_ini.c $(FUZZ_ENGINE_OBJ)
	@mkdir -p build-fuzz
	clang++ -x c -std=c11 -D_GNU_SOURCE $(FUZZ_OBJ_FLAGS) -c tests/fuzz/fuzz_ini.c -o build-fuzz/obj/fuzz_ini.o
	clang++ -fsanitize=fuzzer,address,undefined build-fuzz/obj/fuzz_ini.o $(FUZZ_ENGINE_OBJ) \
		$(PKG_LIBS) -pthread -lm -o $@
fuzz: deps $(FUZZ_SRC:tests/fuzz/%.c=build-fuzz/%)
	@for f in $(FUZZ_SRC:tests/fuzz/%.c=build-fuzz/%); do \
		mkdir -p $$f-corpus; \
		echo "== $$f: $(FUZZ_SECONDS) s"; \
		seeds=; [ $$f = build-fuzz/fuzz_ini ] && seeds=conf/planets; \
		if $$f -max_total_time=$(FUZZ_SECONDS) -print_final_stats=1 $$f-corpus $$seeds >$$f.log 2>&1; \
		then grep -E 'stat::number_of_executed_units' $$f.log; \
		else tail -n 40 $$f.log; echo "$$f: found a failure (crash input saved in ./)"; exit 1; fi; \
	done

# Install (no tests, no benches): the programs in $(BINDIR); the config and the planets in
# $(CONFDIR) (kept if present: the admin's files), the planets' file paths pointed at
# $(STATEDIR), where the shipped planets' data (data/, from make data) go; the systemd units
# made from systemd/*.in with these paths in $(UNITDIR), the group clipmap (sysusers.d), man
# pages (when scdoc is here), docs, bash completion, and CesiumJS for the HTTP endpoint's
# browser page (from $(BUILD)/npm, put there by make deps) in $(DATADIR)/cesium, where the
# installed clipmapd looks for it (BINDIR/../share/clipmap/cesium). DESTDIR stages everything; a real install
# (no DESTDIR; RUN_SYSUSERS=no skips it) then creates the group with systemd-sysusers. `make uninstall` removes what
# install put there except the config, the planets and the data.
PREFIX      ?= /usr/local
BINDIR      ?= $(PREFIX)/bin
SYSCONFDIR  ?= /etc
CONFDIR     ?= $(SYSCONFDIR)/clipmap
STATEDIR    ?= /var/lib/clipmap
MANDIR      ?= $(PREFIX)/share/man
DOCDIR      ?= $(PREFIX)/share/doc/clipmap
DATADIR     ?= $(PREFIX)/share/clipmap
CESIUM_BUILD := $(BUILD)/npm/node_modules/cesium/Build/Cesium
UNITDIR     ?= $(if $(filter /usr,$(PREFIX)),/usr/lib/systemd/system,$(SYSCONFDIR)/systemd/system)
SYSUSERSDIR ?= $(PREFIX)/lib/sysusers.d
BASHCOMPDIR ?= $(PREFIX)/share/bash-completion/completions
RUN_SYSUSERS ?= $(if $(DESTDIR),no,yes)
MAN_SRC     := $(wildcard docs/man/*.scd)
MAN_PAGES   := $(MAN_SRC:docs/man/%.scd=$(BUILD)/man/%)
SCDOC       := $(shell command -v scdoc 2>/dev/null)
UNIT_SED    := s\#@BINDIR@\#$(BINDIR)\#g; s\#@CONFDIR@\#$(CONFDIR)\#g; s\#@DOCDIR@\#$(DOCDIR)\#g
PLANET_DATA := $(wildcard data/earth/*.tif data/earth/*.gpkg data/moon/*.tif data/mars/*.tif)

$(BUILD)/man/%: docs/man/%.scd
	@mkdir -p $(dir $@)
	scdoc < $< > $@
man: $(MAN_PAGES)
# Phony, so they follow the paths of each make run (no pattern rule: phony targets skip them).
$(BUILD)/systemd/clipmapd.service $(BUILD)/systemd/clipmapd.socket:
	@mkdir -p $(dir $@)
	sed '$(UNIT_SED)' systemd/$(notdir $@).in > $@
$(BUILD)/systemd/clipmapd.conf: conf/clipmapd.conf
	@mkdir -p $(dir $@)
	sed 's#^planets = /etc/clipmap/planets#planets = $(CONFDIR)/planets#' $< > $@
.PHONY: man uninstall $(BUILD)/systemd/clipmapd.service $(BUILD)/systemd/clipmapd.socket \
	$(BUILD)/systemd/clipmapd.conf

install: $(PROGS) $(BUILD)/systemd/clipmapd.service $(BUILD)/systemd/clipmapd.socket \
		$(BUILD)/systemd/clipmapd.conf $(if $(SCDOC),$(MAN_PAGES))
	install -d $(DESTDIR)$(BINDIR) $(DESTDIR)$(CONFDIR)/planets $(DESTDIR)$(UNITDIR) \
		$(DESTDIR)$(SYSUSERSDIR) $(DESTDIR)$(DOCDIR) $(DESTDIR)$(BASHCOMPDIR) $(DESTDIR)$(STATEDIR)
	install -m 755 $(PROGS) $(DESTDIR)$(BINDIR)/
	test -e $(DESTDIR)$(CONFDIR)/clipmapd.conf || \
		install -m 644 $(BUILD)/systemd/clipmapd.conf $(DESTDIR)$(CONFDIR)/clipmapd.conf
	for f in conf/planets/*.ini; do \
		t=$(DESTDIR)$(CONFDIR)/planets/$$(basename $$f); test -e $$t && continue; \
		sed 's#^path = \.\./\.\./data/#path = $(STATEDIR)/#' $$f > $$t && chmod 644 $$t || exit 1; done
	for f in conf/planets/*.geojson; do t=$(DESTDIR)$(CONFDIR)/planets/$$(basename $$f); \
		test -e $$t || install -m 644 $$f $$t || exit 1; done
	for f in $(PLANET_DATA); do \
		d=$(DESTDIR)$(STATEDIR)/$$(basename $$(dirname $$f)); \
		install -d $$d && install -m 644 $$f $$d/ || exit 1; done
	install -m 644 $(BUILD)/systemd/clipmapd.service $(BUILD)/systemd/clipmapd.socket \
		$(DESTDIR)$(UNITDIR)/
	install -m 644 systemd/clipmap.sysusers $(DESTDIR)$(SYSUSERSDIR)/clipmap.conf
	install -m 644 README.md LICENSE docs/ARCHITECTURE.md docs/PLANETS.md docs/PROTOCOL.md \
		docs/FLEET.md conf/redis.conf.example $(DESTDIR)$(DOCDIR)/
	install -m 644 scripts/clipmapctl.bash-completion $(DESTDIR)$(BASHCOMPDIR)/clipmapctl
	@if [ -f $(CESIUM_BUILD)/Cesium.js ]; then \
		rm -rf $(DESTDIR)$(DATADIR)/cesium && install -d $(DESTDIR)$(DATADIR)/cesium && \
		cp -RL $(CESIUM_BUILD)/. $(DESTDIR)$(DATADIR)/cesium/ && \
		chmod -R u+rwX,go+rX,go-w $(DESTDIR)$(DATADIR)/cesium || exit 1; \
	else echo "make install: no CesiumJS in $(BUILD)/npm (make deps installs it):" \
		"the HTTP endpoint's browser page will be off"; fi
	$(if $(SCDOC),for m in $(MAN_PAGES); do s=$${m##*.}; install -d $(DESTDIR)$(MANDIR)/man$$s && \
		install -m 644 $$m $(DESTDIR)$(MANDIR)/man$$s/ || exit 1; done, \
		@echo "make install: scdoc not found: no man pages (make deps installs it)")
	$(if $(filter yes,$(RUN_SYSUSERS)),-command -v systemd-sysusers >/dev/null && \
		systemd-sysusers $(SYSUSERSDIR)/clipmap.conf)
	@echo "installed; then: systemctl daemon-reload && systemctl enable --now clipmapd.socket"

uninstall:
	rm -f $(addprefix $(DESTDIR)$(BINDIR)/,clipmapd clipmapctl clipmapctl-offline clipmapview) \
		$(DESTDIR)$(UNITDIR)/clipmapd.service $(DESTDIR)$(UNITDIR)/clipmapd.socket \
		$(DESTDIR)$(SYSUSERSDIR)/clipmap.conf $(DESTDIR)$(BASHCOMPDIR)/clipmapctl \
		$(foreach m,$(MAN_SRC:docs/man/%.scd=%),$(DESTDIR)$(MANDIR)/man$(subst .,,$(suffix $(m)))/$(m))
	rm -rf $(DESTDIR)$(DOCDIR) $(DESTDIR)$(DATADIR)/cesium
	rmdir $(DESTDIR)$(DATADIR) 2>/dev/null || true
	@echo "kept: $(DESTDIR)$(CONFDIR) (config, planets), $(DESTDIR)$(STATEDIR) (data), the group clipmap"

clean:
	rm -rf build build-asan build-tsan build-fuzz

-include $(shell find $(BUILD) -name '*.d' 2>/dev/null)
