# Builds and installs temc's C library: headers, shared library (with SONAME
# libtemc.so.MAJOR), static library and a pkg-config file.
#   make                          # cargo build --release --lib, plus libtemc.so.MAJOR
#                                 # beside libtemc.so: link and run from the build folder
#   make install PREFIX=/opt/temc # then: cc app.c $(pkg-config --cflags --libs temc)
#   make uninstall PREFIX=/opt/temc
# DESTDIR is honoured for staged installs; CARGO_TARGET_DIR for the build folder.
PREFIX     ?= /usr/local
LIBDIR     ?= $(PREFIX)/lib
INCLUDEDIR ?= $(PREFIX)/include
TARGET_DIR ?= $(or $(CARGO_TARGET_DIR),target)
CARGO      ?= cargo
VERSION    := $(shell sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -n 1)
MAJOR      := $(firstword $(subst ., ,$(VERSION)))
LIB        := $(TARGET_DIR)/release

all: lib

# The linker reads libtemc.so; the program then asks the loader for the SONAME,
# libtemc.so.MAJOR, which cargo does not make: link it beside, so that
#   cc app.c -Iinclude -L$(LIB) -ltemc && LD_LIBRARY_PATH=$(LIB) ./a.out
# works from the build folder (tests/c_examples.rs runs this).
lib:
	$(CARGO) build --release --lib
	ln -sf libtemc.so $(LIB)/libtemc.so.$(MAJOR)

install: lib install-only

# Installs what `make lib` (or any `cargo build --release`) left in the target folder.
install-only:
	install -d $(DESTDIR)$(LIBDIR)/pkgconfig $(DESTDIR)$(INCLUDEDIR)
	install -m 644 include/temc.h $(DESTDIR)$(INCLUDEDIR)/temc.h
	install -m 644 include/temc_config.h $(DESTDIR)$(INCLUDEDIR)/temc_config.h
	install -m 644 include/temc.hpp $(DESTDIR)$(INCLUDEDIR)/temc.hpp
	install -m 755 $(LIB)/libtemc.so $(DESTDIR)$(LIBDIR)/libtemc.so.$(VERSION)
	ln -sf libtemc.so.$(VERSION) $(DESTDIR)$(LIBDIR)/libtemc.so.$(MAJOR)
	ln -sf libtemc.so.$(MAJOR) $(DESTDIR)$(LIBDIR)/libtemc.so
	install -m 644 $(LIB)/libtemc.a $(DESTDIR)$(LIBDIR)/libtemc.a
	sed -e 's|@PREFIX@|$(PREFIX)|' -e 's|@LIBDIR@|$(LIBDIR)|' \
	    -e 's|@INCLUDEDIR@|$(INCLUDEDIR)|' -e 's|@VERSION@|$(VERSION)|' \
	    temc.pc.in > $(DESTDIR)$(LIBDIR)/pkgconfig/temc.pc

uninstall:
	rm -f $(DESTDIR)$(INCLUDEDIR)/temc.h $(DESTDIR)$(INCLUDEDIR)/temc_config.h \
	    $(DESTDIR)$(INCLUDEDIR)/temc.hpp $(DESTDIR)$(LIBDIR)/libtemc.so* \
	    $(DESTDIR)$(LIBDIR)/libtemc.a $(DESTDIR)$(LIBDIR)/pkgconfig/temc.pc

.PHONY: all lib install install-only uninstall
