# dofray in a container, for render farms (docs/farm.md, examples/kubernetes/). From the
# repository root:
#
#   docker build -t dofray:latest .
#   docker run --rm -v "$PWD:/work" dofray:latest render scenes/gallery.toml -o gallery.png
#
# Build arguments:
#   TARGET_CPU=x86-64-v3  what .cargo/config.toml builds for (AVX2 + FMA: x86-64 CPUs since
#                         2013-2015); --build-arg TARGET_CPU=x86-64 for farms with older nodes.
#   DOFRAY_GIT_COMMIT     the commit `dofray --version` reports (.git is not sent to the build):
#                         --build-arg DOFRAY_GIT_COMMIT=$(git rev-parse --short HEAD)
#
# Two stages. The builder is Rust's official Debian 12 image (Debian 12's own rustc, 1.63, is
# too old for dofray: edition 2024, rust-version 1.85) with Debian 12's Embree 3 and libclang,
# the packages README.md's first command installs; it runs the README's build, in release,
# and scripts/install-capi.sh (the C library, which CI tests too). The runtime image is
# debian:bookworm-slim with Embree's runtime package, dofray at /usr/local/bin/dofray and
# libdofray.so (+ dofray.h, dofray.pc) under /usr/local, running as an unprivileged user
# (uid 10001) in /work. Docker cannot run on CI machines: scripts/docker-check.sh (run by
# .ci/run) checks there that the packages named here exist in Debian 12 and provide every
# library the binary and libdofray.so load.

FROM rust:1-bookworm AS builder
RUN apt-get update \
 && apt-get install -y --no-install-recommends libembree-dev libclang-dev \
 && rm -rf /var/lib/apt/lists/*
ARG TARGET_CPU=x86-64-v3
ENV RUSTFLAGS="-C target-cpu=${TARGET_CPU}"
ARG DOFRAY_GIT_COMMIT=
ENV DOFRAY_GIT_COMMIT=${DOFRAY_GIT_COMMIT}
WORKDIR /src
COPY . .
# The cache mounts (BuildKit: Docker's builder since 23.0; Podman and Buildah have them too)
# keep downloaded crates and compiled dependencies between builds; what the runtime stage
# needs is staged in /staging by the same step. libdofray.a stays behind: it is
# for linking, which happens elsewhere.
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    --mount=type=cache,target=/src/target \
    cargo build --release --locked --bin dofray \
 && install -D -m 0755 target/release/dofray /staging/usr/local/bin/dofray \
 && DESTDIR=/staging scripts/install-capi.sh /usr/local --locked \
 && rm /staging/usr/local/lib/libdofray.a

FROM debian:bookworm-slim
RUN apt-get update \
 && apt-get install -y --no-install-recommends libembree3-3 \
 && rm -rf /var/lib/apt/lists/*
COPY --from=builder /staging/usr/local/ /usr/local/
RUN ldconfig \
 && groupadd --system --gid 10001 dofray \
 && useradd --system --uid 10001 --gid dofray --create-home --home-dir /home/dofray dofray \
 && install -d -o dofray -g dofray /work \
 && dofray render --width 32 --height 24 --quiet -o /tmp/smoke.png \
 && rm /tmp/smoke.png
# Numeric, so that Kubernetes' runAsNonRoot can verify it.
USER 10001:10001
WORKDIR /work
ENTRYPOINT ["dofray"]
CMD ["--help"]
