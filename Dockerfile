# StillPoint on Debian 12: the same steps CI runs (scripts/setup.sh installs the Debian packages,
# scripts/build.sh builds), then `cmake --install` into /usr/local. Not built in CI.
#
#   docker build -t stillpoint .
#   docker run --rm stillpoint stillpoint run --out /tmp/out           # the bundled demo
#   docker run --rm -v ~/tum:/data stillpoint stillpoint run --dataset /data/rgbd_dataset_freiburg3_walking_xyz \
#       --camera /usr/local/share/stillpoint/config/camera/tum_fr3.yaml --out /data/out
#   docker run --rm stillpoint python3 /usr/local/share/stillpoint/examples/track_sequence.py
FROM debian:12
ENV DEBIAN_FRONTEND=noninteractive
WORKDIR /src/stillpoint
COPY . .
# setup.sh runs apt-get as root here; its package list is the one CI installs.
RUN scripts/setup.sh && rm -rf /var/lib/apt/lists/*
RUN SP_BUILD_DIR=/src/build scripts/build.sh -DSP_BUILD_TESTS=OFF \
 && cmake --install /src/build --prefix /usr/local \
 && ldconfig \
 && rm -rf /src/build
ENV PYTHONPATH=/usr/local/lib/python3/dist-packages
WORKDIR /work
CMD ["stillpoint", "--help"]
