# Multi-stage build on Debian trixie, whose own libembree-dev is Embree 4 (bookworm has none,
# so scripts/embree.sh unpacks Intel's build there instead). The other build packages are
# scripts/packages.txt, the same file scripts/setup.sh installs from, so the two cannot drift
# apart (tests/deploy.rs checks both files).
FROM rust:1-trixie AS build
WORKDIR /src
COPY scripts/packages.txt scripts/packages.txt
RUN apt-get update && grep -v '^\s*#' scripts/packages.txt | grep -v '^\s*$' \
    | xargs apt-get install -y --no-install-recommends libembree-dev && rm -rf /var/lib/apt/lists/*
COPY . .
RUN scripts/oidn.sh && cargo build --release --locked

FROM debian:trixie-slim
RUN apt-get update && apt-get install -y --no-install-recommends libembree4-4 libfontconfig1 fonts-dejavu-core ca-certificates \
    && rm -rf /var/lib/apt/lists/*
COPY --from=build /src/target/release/relume /usr/local/bin/relume
# Open Image Denoise: the binary's rpath includes $ORIGIN/../lib/relume. Its TBB and Debian's
# (libembree4-4's) share the SONAME libtbb.so.12, so the loader maps one TBB for both.
COPY --from=build /src/.deps/oidn/lib /usr/local/lib/relume
COPY --from=build /src/scenes /usr/share/relume/scenes
WORKDIR /usr/share/relume
ENTRYPOINT ["relume"]
EXPOSE 8080
# Inside a container the service must listen beyond loopback, so it needs RELUME_TOKEN set.
CMD ["serve", "--addr", "0.0.0.0:8080", "--scenes", "/usr/share/relume/scenes"]
