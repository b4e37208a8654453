# clipmap — plain Makefile, out-of-tree objects in build/ (BUILD=... for variants).
#   make            build everything
#   make check      install deps, build, run every test
#   make asan/tsan  the same suite under sanitizers (build-asan/, build-tsan/)
#   make bench      benchmarks that print figures
#   make deps       install the Debian packages the project needs (and prepare data/)
#   make data       install the planet data packages and import them into data/

BUILD   ?= build
CC      ?= cc
CXX     ?= g++
PKGS    := OpenImageIO geographiclib libxxhash libzstd liblz4 libsystemd gdal lmdb
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

.PHONY: all check test layers asan tsan bench bench-keepup deps clean demo data shader-check fuzz install
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
	$(CC) $(LDFLAGS) $^ $(LDLIBS) -o $@
$(BUILD)/clipmapctl: $(BUILD)/client/ctl/clipmapctl.o $(CTL_LIB) $(CLIENT_LIB) $(ENGINE_LIB) $(COMMON_LIB)
	$(CC) $(LDFLAGS) $^ $(LDLIBS) -o $@
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
	$$(CC) $$(LDFLAGS) $$^ $$(LDLIBS) $(if $(filter $(1),$(GL_TESTS)),$$(GL_LIBS)) -o $$@
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
	@sh tests/run.sh $(BUILD)

test: all shader-check layers
	@sh tests/run.sh $(BUILD)

# The wings' include rule (docs/ARCHITECTURE.md).
layers:
	@sh tests/layers.sh

shader-check:
	@for s in $(SHADERS); do glslangValidator $$s >/dev/null || { glslangValidator $$s; exit 1; }; done
	@echo "shaders: $(words $(SHADERS)) checked by glslangValidator"


asan: export ASAN_OPTIONS = detect_leaks=1:abort_on_error=0
asan: export LSAN_OPTIONS = suppressions=$(CURDIR)/tests/lsan.supp:print_suppressions=0
asan: export UBSAN_OPTIONS = print_stacktrace=1:halt_on_error=1
asan:
	@$(MAKE) --no-print-directory BUILD=build-asan OPT="-O1 -g" \
	  SAN="-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=all" test

tsan: export TSAN_OPTIONS = suppressions=$(CURDIR)/tests/tsan.supp:halt_on_error=1:second_deadlock_stack=1
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

# libFuzzer targets (clang): each tests/fuzz/fuzz_NAME.c runs FUZZ_SECONDS on its corpus.
FUZZ_SECONDS ?= 60
FUZZ_SRC := $(wildcard tests/fuzz/fuzz_*.c)
FUZZ_LIBSRC := common/proto.c common/proto_write.c common/tilecodec.c common/pixfmt.c common/grid.c \
               common/xalloc.c common/errbuf.c
FUZZ_FLAGS := -std=c11 -D_GNU_SOURCE -g -O1 -fsanitize=fuzzer,address,undefined \
              -fno-sanitize-recover=all -iquote . -iquote daemon
build-fuzz/%: tests/fuzz/%.c $(FUZZ_LIBSRC)
	@mkdir -p build-fuzz
	clang $(FUZZ_FLAGS) $^ $(shell pkg-config --libs libzstd liblz4 libxxhash) -lm -o $@
fuzz: deps $(FUZZ_SRC:tests/fuzz/%.c=build-fuzz/%)
	@for f in $(FUZZ_SRC:tests/fuzz/%.c=build-fuzz/%); do \
		mkdir -p $$f-corpus; \
		echo "== $$f: $(FUZZ_SECONDS) s"; \
		if $$f -max_total_time=$(FUZZ_SECONDS) -print_final_stats=1 $$f-corpus >$$f.log 2>&1; \
		then grep -E 'stat::number_of_executed_units' $$f.log; \
		else tail -n 40 $$f.log; echo "$$f: found a failure (crash input saved in ./)"; exit 1; fi; \
	done

# Install: binaries in $(PREFIX)/bin (the units expect /usr/local/bin), the config and the
# planets in /etc/clipmap (kept if present), the units in /etc/systemd/system. DESTDIR stages.
PREFIX ?= /usr/local
install: all
	install -d $(DESTDIR)$(PREFIX)/bin $(DESTDIR)/etc/clipmap/planets $(DESTDIR)/etc/systemd/system
	install -m 755 $(PROGS) $(DESTDIR)$(PREFIX)/bin/
	test -e $(DESTDIR)/etc/clipmap/clipmapd.conf || \
		install -m 644 conf/clipmapd.conf $(DESTDIR)/etc/clipmap/clipmapd.conf
	for f in conf/planets/*.ini; do \
		test -e $(DESTDIR)/etc/clipmap/planets/$$(basename $$f) || \
		install -m 644 $$f $(DESTDIR)/etc/clipmap/planets/; done
	install -m 644 systemd/clipmapd.service systemd/clipmapd.socket $(DESTDIR)/etc/systemd/system/

clean:
	rm -rf build build-asan build-tsan build-fuzz

-include $(shell find $(BUILD) -name '*.d' 2>/dev/null)
