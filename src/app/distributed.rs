//! `--distributed`: one volume split over MPI ranks (feature `mpi`), rendered
//! sort-last with [`shearwarp::bricks`], launched as
//! `mpirun -np N shearwarp render|rotate|bench … --distributed`.
//!
//! - **Bricks.** Rank `r` owns brick `r` of the k-d split of the volume into
//!   `N` bricks ([`shearwarp::bricks::split`]) and holds it with its ghost
//!   voxels, nothing else. A raw or `.den` file or an NRRD with raw
//!   encoding (attached, or a detached header and its data file) is read
//!   brick by brick, each rank seeking to its own rows
//!   ([`shearwarp::data::io::read_box`], with the loader's own header
//!   parse); any other input (a gzip NRRD, NIfTI, DICOM, a phantom, or any
//!   file under `--orientation`) is read whole by rank 0, which sends each
//!   rank its brick and then lets go of the volume: rank 0 holds the whole
//!   volume while it scatters. `--json` says which (`read`: `seek` or
//!   `scatter`).
//! - **Classification.** Every rank computes the value statistics of its
//!   owned voxels; rank 0 merges them and broadcasts the whole volume's, so
//!   every brick is classified as one renderer classifies the whole volume
//!   (the presets, the value range).
//! - **A frame.** Rank 0 owns the camera and the tissue and broadcasts them;
//!   every rank renders its brick into its share of the whole volume's
//!   intermediate grid ([`shearwarp::render::Renderer::render_brick`]) and
//!   sends the rectangle it covers to rank 0 (direct send to one
//!   compositor), which composites them front to back in the view's brick
//!   order, warps once and writes the output.
//! - **`bench`.** The binary and RLE variants of the benchmark's parallel
//!   matrix, each over the benchmark's views and rounds: rank 0's frame
//!   time and every rank's render, compositing and bytes a frame; the
//!   variants a distributed frame does not run are listed as skipped.
//! - **Faults.** After every step that can fail, the ranks agree: each
//!   sends rank 0 its error (if any); rank 0 prints the first with its rank
//!   and aborts the whole job (`MPI_Abort`), so no rank hangs and nothing
//!   is written.

use std::time::Instant;

use anyhow::{Context, Result, anyhow};
use mpi::topology::SimpleCommunicator;
use mpi::traits::*;
use shearwarp::bricks::{Brick, Compositor, Partial, Tree, split};
use shearwarp::composite::Mode;
use shearwarp::data::io;
use shearwarp::data::orientation::PatientFrame;
use shearwarp::data::stats::ValueStats;
use shearwarp::data::volume::{Volume, VoxelData};
use shearwarp::render::{Method, Renderer, Settings};
use shearwarp::view::{Camera, NamedView, one_bit_step_deg, rotate_eye, standard_views};
use shearwarp::warp::Image;

use crate::app::args::{RenderArgs, VolumeArgs};
use crate::app::bench::{BenchCmd, Variant, variants_of};
use crate::app::{RenderJob, RotateJob};

/// The MPI world and what this rank sent and received.
struct Comm {
    world: SimpleCommunicator,
    rank: usize,
    n: usize,
    sent: u64,
    received: u64,
}

impl Comm {
    /// Rank 0's `data` on every rank.
    fn bcast(&mut self, data: Option<Vec<u8>>) -> Vec<u8> {
        let root = self.world.process_at_rank(0);
        let mut len = data.as_ref().map_or(0u64, |d| d.len() as u64);
        root.broadcast_into(&mut len);
        let mut buf = data.unwrap_or_else(|| vec![0u8; len as usize]);
        root.broadcast_into(&mut buf[..]);
        if self.rank == 0 {
            self.sent += len * (self.n as u64 - 1);
        } else {
            self.received += len;
        }
        buf
    }

    /// Every rank's `mine`, in rank order, on rank 0 (`None` elsewhere).
    fn gather(&mut self, mine: Vec<u8>) -> Option<Vec<Vec<u8>>> {
        if self.rank == 0 {
            let mut all = vec![mine];
            for r in 1..self.n {
                let (v, _) = self.world.process_at_rank(r as i32).receive_vec::<u8>();
                self.received += v.len() as u64;
                all.push(v);
            }
            Some(all)
        } else {
            self.world.process_at_rank(0).send(&mine[..]);
            self.sent += mine.len() as u64;
            None
        }
    }

    /// Sends `data` to rank `to`.
    fn send_to(&mut self, to: usize, data: &[u8]) {
        self.world.process_at_rank(to as i32).send(data);
        self.sent += data.len() as u64;
    }

    /// Receives what rank `from` sent this rank.
    fn receive(&mut self, from: usize) -> Vec<u8> {
        let (v, _) = self.world.process_at_rank(from as i32).receive_vec::<u8>();
        self.received += v.len() as u64;
        v
    }

    /// Every rank's result of one step: when a rank failed, rank 0 prints
    /// its error and aborts the job (every rank exits); else every rank goes on.
    fn agree<T>(&mut self, r: Result<T>) -> T {
        let (sent, received) = (self.sent, self.received);
        let msg = match &r {
            Ok(_) => vec![],
            Err(e) => format!("{e:#}").into_bytes(),
        };
        if let Some(all) = self.gather(msg)
            && let Some((rank, m)) = all.iter().enumerate().find(|(_, m)| !m.is_empty())
        {
            let who = if self.n > 1 { format!("rank {rank} of {}: ", self.n) } else { String::new() };
            eprintln!("error: {who}{}", String::from_utf8_lossy(m));
            self.world.abort(2);
        }
        self.bcast(Some(vec![1]).filter(|_| self.rank == 0));
        // (the agreement is not the frame's traffic)
        (self.sent, self.received) = (sent, received);
        match r {
            Ok(t) => t,
            // rank 0 aborted the job on this error: not reached
            Err(_) => self.world.abort(2),
        }
    }
}

/// One rank's brick, renderer and the split's geometry.
struct Node {
    comm: Comm,
    dims: [usize; 3],
    spacing: [f32; 3],
    bricks: Vec<Brick>,
    tree: Tree,
    renderer: Renderer,
    name: String,
    /// Rank 0: the camera of the render arguments.
    camera: Option<Camera>,
    /// Milliseconds to read this rank's brick (and, on rank 0, to scatter).
    load_ms: f64,
    /// How the brick came: `"seek"` (this rank read it from the file) or
    /// `"scatter"` (rank 0 read the whole volume and sent it).
    read: &'static str,
    /// Peak resident bytes once the brick was read (before the renderer).
    read_peak: Option<u64>,
    /// Rank 0: the whole volume's frame, kept from frame to frame.
    compositor: Option<Compositor>,
}

fn voxel_bytes(v: &Volume) -> Vec<u8> {
    let mut b = Vec::new();
    b.extend(v.dims().map(|d| d as u64).iter().flat_map(|d| d.to_le_bytes()));
    b.extend(v.spacing().iter().flat_map(|s| s.to_le_bytes()));
    match v.data() {
        VoxelData::U8(x) => {
            b.push(0);
            b.extend_from_slice(x);
        }
        VoxelData::U16(x) => {
            b.push(1);
            x.iter().for_each(|y| b.extend(y.to_le_bytes()));
        }
        VoxelData::I16(x) => {
            b.push(2);
            x.iter().for_each(|y| b.extend(y.to_le_bytes()));
        }
        VoxelData::F32(x) => {
            b.push(3);
            x.iter().for_each(|y| b.extend(y.to_le_bytes()));
        }
    }
    b
}

fn volume_from_bytes(b: &[u8]) -> Result<Volume> {
    let bad = || anyhow!("internal: a brick of {} bytes is malformed", b.len());
    if b.len() < 37 {
        return Err(bad());
    }
    let u = |i: usize| u64::from_le_bytes(b[8 * i..8 * i + 8].try_into().expect("8 bytes")) as usize;
    let f = |i: usize| f32::from_le_bytes(b[24 + 4 * i..28 + 4 * i].try_into().expect("4 bytes"));
    let (dims, spacing, body) = ([u(0), u(1), u(2)], [f(0), f(1), f(2)], &b[37..]);
    let data = match b[36] {
        0 => VoxelData::U8(body.to_vec()),
        1 => VoxelData::U16(body.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect()),
        2 => VoxelData::I16(body.chunks_exact(2).map(|c| i16::from_le_bytes([c[0], c[1]])).collect()),
        3 => VoxelData::F32(body.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes"))).collect()),
        _ => return Err(bad()),
    };
    Ok(Volume::new(dims, spacing, data)?)
}

fn camera_bytes(c: &Camera) -> Vec<u8> {
    let mut b = Vec::new();
    c.rotation.to_cols_array().iter().chain([c.zoom.unwrap_or(f64::NAN)].iter()).for_each(|x| b.extend(x.to_le_bytes()));
    c.size.iter().for_each(|s| b.extend((*s as u64).to_le_bytes()));
    b
}

fn camera_from_bytes(b: &[u8]) -> Camera {
    let f = |i: usize| f64::from_le_bytes(b[8 * i..8 * i + 8].try_into().expect("8 bytes"));
    let rot: [f64; 9] = std::array::from_fn(f);
    let zoom = Some(f(9)).filter(|z| !z.is_nan());
    let size = [f(10).to_bits() as usize, f(11).to_bits() as usize];
    Camera { rotation: glam::DMat3::from_cols_array(&rot), zoom, size }
}

/// What every rank finds of the input before reading: the seekable layout
/// of a raw, `.den` or uncompressed NRRD file (without `--orientation`,
/// which may reverse voxels as it loads), else `None` (rank 0 reads the
/// whole volume).
fn seekable(v: &VolumeArgs) -> Result<Option<io::Layout>> {
    let (path, format) = match (&v.file, &v.raw, &v.den) {
        (Some(p), _, _) => (p, v.format),
        (_, Some(p), _) => (p, Some(io::Format::Raw)),
        (_, _, Some(p)) => (p, Some(io::Format::Den)),
        _ => return Ok(None),
    };
    if v.orientation.is_some() {
        return Ok(None);
    }
    let raw = match (v.dims, v.voxel_type) {
        (Some(dims), Some(t)) => {
            let mut spec = io::RawSpec::new(dims, t);
            spec.big_endian = v.big_endian;
            spec.header_bytes = v.header_bytes;
            Some(spec)
        }
        (None, None) => None,
        _ => return Err(anyhow!(crate::app::Usage("raw files need both --dims X,Y,Z and --type (or a JSON sidecar)".into()))),
    };
    let layout = io::seekable_layout(path, &io::LoadOptions { format, raw })?;
    Ok(layout.map(|mut s| {
        if let Some(sp) = v.spacing {
            s.spacing = sp;
        }
        s
    }))
}

impl Node {
    /// MPI up, the volume split, this rank's brick read, the statistics
    /// agreed and the renderer made: every step agreed by every rank.
    /// `camera` makes rank 0's camera from the volume's patient frame (when
    /// it has one), `renderer` each rank's renderer of its brick.
    fn new(
        universe: &mpi::environment::Universe,
        v: &VolumeArgs,
        camera: impl FnOnce(Option<&PatientFrame>) -> Result<Camera>,
        renderer: impl FnOnce(Volume) -> Result<Renderer>,
    ) -> Node {
        let world = universe.world();
        let (rank, n) = (world.rank() as usize, world.size() as usize);
        let mut comm = Comm { world, rank, n, sent: 0, received: 0 };
        crate::app::set_budget(v.max_memory);
        let t = Instant::now();
        // how the volume comes: every rank reads the file's header (rank 0's error first)
        let spec = comm.agree(seekable(v));
        // rank 0 reads the whole volume when it must (its camera needs its frame)
        let whole = if rank == 0 && spec.is_none() { Some(v.load()) } else { None };
        let whole = comm.agree(whole.transpose());
        let head = if rank == 0 {
            let (dims, spacing) = match (&whole, &spec) {
                (Some((vol, _)), _) => (vol.dims(), vol.spacing()),
                (None, Some(s)) => (s.dims, s.spacing),
                (None, None) => unreachable!("a layout or a volume"),
            };
            let mut b: Vec<u8> = dims.iter().flat_map(|d| (*d as u64).to_le_bytes()).collect();
            spacing.iter().for_each(|x| b.extend(x.to_le_bytes()));
            Some(b)
        } else {
            None
        };
        let head = comm.bcast(head);
        let dims = [0, 1, 2].map(|i| u64::from_le_bytes(head[8 * i..8 * i + 8].try_into().expect("8 bytes")) as usize);
        let spacing = [0, 1, 2].map(|i| f32::from_le_bytes(head[24 + 4 * i..28 + 4 * i].try_into().expect("4 bytes")));
        let split = comm.agree(split(dims, n).map_err(|e| anyhow!(crate::app::Usage(format!("--distributed over {n} ranks: {e}")))));
        let (bricks, tree) = split;
        let me = bricks[rank];
        let name = match (&whole, [&v.file, &v.raw, &v.den].into_iter().flatten().next()) {
            (Some((_, name)), _) => name.clone(),
            (None, Some(p)) => p.display().to_string(),
            _ => String::new(),
        };
        let frame = whole.as_ref().and_then(|(v, _)| v.frame()).or(spec.as_ref().and_then(|s| s.frame.as_ref()));
        let camera = if rank == 0 { Some(camera(frame)) } else { None };
        let camera = comm.agree(camera.transpose());
        // this rank's brick: read by seeking, or scattered by rank 0
        let brick: Result<Volume> = match (&spec, whole) {
            (Some(s), _) => io::read_box(s, me.ghosted.map(|g| g[0]), me.ghosted.map(|g| g[1])).map_err(anyhow::Error::from),
            (None, Some((vol, _))) => {
                // rank 0's brick, then every other rank's (an empty message when
                // one cannot be cut: that rank fails, after rank 0's own error)
                let mut mine = bricks[0].extract(&vol).map_err(anyhow::Error::from);
                for (r, b) in bricks.iter().enumerate().skip(1) {
                    match b.extract(&vol) {
                        Ok(p) if mine.is_ok() => comm.send_to(r, &voxel_bytes(&p)),
                        Ok(_) => comm.send_to(r, &[]),
                        Err(e) => {
                            comm.send_to(r, &[]);
                            if mine.is_ok() {
                                mine = Err(e.into());
                            }
                        }
                    }
                }
                drop(vol);
                mine
            }
            (None, None) => volume_from_bytes(&comm.receive(0)),
        };
        let brick = brick.and_then(|b| {
            let bytes = b.bytes();
            match crate::app::budget().filter(|&m| bytes > m) {
                Some(m) => Err(anyhow!(crate::app::Usage(format!(
                    "{name}: brick {rank} alone holds {}, over the memory budget of {} (--max-memory)",
                    shearwarp::fmt::fmt_bytes(bytes),
                    shearwarp::fmt::fmt_bytes(m)
                )))),
                None => Ok(b),
            }
        });
        let brick = comm.agree(brick.with_context(|| format!("reading brick {rank} (voxels {:?})", me.ghosted)));
        let load_ms = t.elapsed().as_secs_f64() * 1e3;
        let read_peak = crate::app::peak_rss_bytes();
        // the statistics of the owned voxels, merged on rank 0, the whole volume's everywhere
        let own_stats = comm.agree(me.owned_stats(&brick).map_err(anyhow::Error::from));
        let merged = comm.gather(own_stats.to_bytes()).map(|all| {
            let mut it = all.iter().filter_map(|b| ValueStats::from_bytes(b));
            let first = it.next().expect("rank 0's statistics");
            it.fold(first, |a, b| a.merge(&b)).to_bytes()
        });
        let stats = comm.bcast(merged);
        let mut stats = comm.agree(ValueStats::from_bytes(&stats).ok_or_else(|| anyhow!("internal: the merged statistics are malformed")));
        // f32 voxels: the presets' histogram, summed over the bricks
        if let Some((bins, range)) = shearwarp::bricks::preset_histogram_range(&brick, &stats) {
            let h = comm.agree(me.owned_histogram(&brick, bins, range).map_err(anyhow::Error::from));
            let sum = comm.gather(h.iter().flat_map(|x| x.to_le_bytes()).collect()).map(|all| {
                let mut total = vec![0u64; bins];
                for b in &all {
                    for (t, c) in total.iter_mut().zip(b.chunks_exact(8)) {
                        *t += u64::from_le_bytes(c.try_into().expect("8 bytes"));
                    }
                }
                total.iter().flat_map(|x| x.to_le_bytes()).collect()
            });
            let sum = comm.bcast(sum);
            let h = sum.chunks_exact(8).map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes"))).collect();
            stats = stats.with_histogram(range[0], range[1], h);
        }
        let brick = brick.with_stats(stats);
        let renderer = comm.agree(renderer(brick));
        let read = if spec.is_some() { "seek" } else { "scatter" };
        Node { comm, dims, spacing, bricks, tree, renderer, name, camera, load_ms, read, read_peak, compositor: None }
    }

    /// One frame: rank 0's camera and tissue broadcast, every brick
    /// rendered, the partial images composited on rank 0 into `img`.
    fn frame(&mut self, camera: Option<Camera>, tissue: Option<usize>, img: &mut Image) -> FrameRecord {
        let (sent0, received0) = (self.comm.sent, self.comm.received);
        let mut msg = camera.as_ref().map(camera_bytes).unwrap_or_default();
        msg.extend((tissue.unwrap_or(0) as u64).to_le_bytes());
        let msg = self.comm.bcast((self.comm.rank == 0).then_some(msg));
        let cam = camera_from_bytes(&msg);
        let tissue = u64::from_le_bytes(msg[96..104].try_into().expect("8 bytes")) as usize;
        let me = self.bricks[self.comm.rank];
        let t = Instant::now();
        let settings = self.renderer.settings();
        let r = &mut self.renderer;
        let rendered = (|| -> Result<_> {
            if r.tissues().is_some() {
                r.select_tissue(tissue)?;
            }
            let f = r.render_brick(&cam, &me.view(self.dims))?;
            let grid = shearwarp::bricks::grid_of(&cam, self.dims, self.spacing, &settings)?;
            Ok((f, Partial::of(r.intermediate(), f.rect, f.offset, grid)?))
        })();
        let (f, part) = self.comm.agree(rendered);
        let render_ms = t.elapsed().as_secs_f64() * 1e3;
        // rank 0 takes the partial images one at a time in the view's brick
        // order, compositing each as it comes: it holds one besides its own
        let (mut gather_ms, mut composite_ms) = (0.0, 0.0);
        let composited = if self.comm.rank == 0 {
            let t = Instant::now();
            let comp = &mut self.compositor;
            let (dims, spacing, tree) = (self.dims, self.spacing, &self.tree);
            let mut done = match comp {
                Some(c) => c.reset(&cam, dims, spacing, tree, &settings),
                None => Compositor::new(&cam, dims, spacing, tree, &settings).map(|c| *comp = Some(c)),
            }
            .map_err(anyhow::Error::from);
            // (every rank's image is received even after an error: a sender never waits for ever)
            let order = match (&done, comp.as_ref()) {
                (Ok(()), Some(c)) => c.order().to_vec(),
                _ => (0..self.comm.n).collect(),
            };
            composite_ms += t.elapsed().as_secs_f64() * 1e3;
            for i in order {
                let t = Instant::now();
                let bytes = (i != 0).then(|| self.comm.receive(i));
                gather_ms += t.elapsed().as_secs_f64() * 1e3;
                let t = Instant::now();
                if let (Ok(()), Some(c)) = (&done, comp.as_mut()) {
                    match bytes.map(|b| Partial::from_bytes(&b)) {
                        None => c.add(&part),
                        Some(Ok(p)) => c.add(&p),
                        Some(Err(e)) => done = Err(e.into()),
                    }
                }
                composite_ms += t.elapsed().as_secs_f64() * 1e3;
            }
            let t = Instant::now();
            if let (Ok(()), Some(c)) = (&done, comp.as_mut()) {
                c.finish(&cam, img);
            }
            composite_ms += t.elapsed().as_secs_f64() * 1e3;
            done
        } else {
            let t = Instant::now();
            self.comm.send_to(0, &part.to_bytes());
            gather_ms = t.elapsed().as_secs_f64() * 1e3;
            Ok(())
        };
        self.comm.agree(composited);
        FrameRecord {
            build_ms: f.stats.build_ms,
            render_ms: render_ms - f.stats.build_ms,
            gather_ms,
            composite_ms,
            sent: self.comm.sent - sent0,
            received: self.comm.received - received0,
            covered: part.rgba.len() as u64,
        }
    }

    /// Every rank's records and peak memory, as JSON on rank 0.
    fn ranks_json(&mut self, records: &[FrameRecord]) -> Option<Vec<serde_json::Value>> {
        let me = self.bricks[self.comm.rank];
        let med = |f: &dyn Fn(&FrameRecord) -> f64| {
            let mut v: Vec<f64> = records.iter().map(f).collect();
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied().unwrap_or(0.0)
        };
        let j = serde_json::json!({
            "rank": self.comm.rank, "owned": me.owned, "held": me.ghosted, "read": self.read, "load_ms": self.load_ms,
            "build_ms": records.iter().map(|r| r.build_ms).sum::<f64>(),
            "render_ms": med(&|r| r.render_ms), "gather_ms": med(&|r| r.gather_ms), "composite_ms": med(&|r| r.composite_ms),
            "sent_bytes_per_frame": med(&|r| r.sent as f64), "received_bytes_per_frame": med(&|r| r.received as f64),
            "covered_pixels": med(&|r| r.covered as f64),
            "peak_rss_bytes": crate::app::peak_rss_bytes(), "peak_rss_after_read_bytes": self.read_peak,
            "memory": crate::app::memory_json(&self.renderer),
        });
        self.comm.gather(j.to_string().into_bytes()).map(|all| all.iter().filter_map(|b| serde_json::from_slice(b).ok()).collect())
    }
}

/// One rank's share of one frame.
#[derive(Clone, Copy, Debug, Default)]
struct FrameRecord {
    build_ms: f64,
    /// Shear and render of the brick.
    render_ms: f64,
    /// Rank 0: waiting for and receiving the partial images; others: sending theirs.
    gather_ms: f64,
    /// Rank 0: compositing the partial images and warping.
    composite_ms: f64,
    sent: u64,
    received: u64,
    covered: u64,
}

/// The node of `render` and `rotate`: the camera and renderer of the render arguments.
fn node_of(universe: &mpi::environment::Universe, v: &VolumeArgs, ra: &RenderArgs) -> Node {
    let renderer = |brick| {
        ra.renderer_and_scene(brick).map(|(mut r, _)| {
            r.set_memory_budget(crate::app::budget());
            r
        })
    };
    Node::new(universe, v, |frame| ra.camera(frame), renderer)
}

fn init() -> Result<mpi::environment::Universe> {
    mpi::initialize().ok_or_else(|| anyhow!("MPI is already initialized"))
}

/// The settings a distributed frame refuses, named before any rank reads.
fn check_args(ra: &RenderArgs) -> Result<()> {
    if ra.perspective.is_some() {
        usage!("--distributed renders parallel projections only (drop --perspective)");
    }
    if !ra.clip_plane.is_empty() {
        usage!("--distributed does not take clip planes");
    }
    if ra.reconstruction.is_some_and(|r| r != shearwarp::kernels::Reconstruction::Linear) {
        usage!("--distributed reconstructs linearly only (drop --reconstruction cubic)");
    }
    Ok(())
}

/// `shearwarp render --distributed`.
pub fn render(cmd: &RenderJob) -> Result<()> {
    check_args(cmd.render)?;
    let kind = match crate::app::output::image_kind(cmd.output) {
        Ok(k) => k,
        Err(why) => usage!("-o {why}"),
    };
    let universe = init()?;
    let mut node = node_of(&universe, cmd.volume, cmd.render);
    let cam = node.camera.unwrap_or(Camera::new(glam::DMat3::IDENTITY, [1, 1]));
    let tissue = node.renderer.tissues().map(|(_, c)| c);
    let mut img = Image::new(cam.size[0], cam.size[1]);
    let t = Instant::now();
    let rec = node.frame(node.camera, tissue, &mut img);
    let frame_ms = t.elapsed().as_secs_f64() * 1e3;
    let written = if node.comm.rank == 0 {
        crate::app::output::write_image(cmd.output, kind, &img.to_rgb8()).map_err(anyhow::Error::from)
    } else {
        Ok(())
    };
    node.comm.agree(written);
    let ranks = node.ranks_json(&[rec]);
    if let Some(ranks) = ranks {
        let s = node.renderer.settings();
        if cmd.json {
            let j = serde_json::json!({
                "volume": node.name, "dims": node.dims, "ranks": node.comm.n, "method": s.method.name(), "mode": s.mode.name(),
                "cell": s.cell, "size": cam.size[0], "output": cmd.output, "frame_ms": frame_ms, "per_rank": ranks,
            });
            say!("{j}");
        } else {
            eprintln!(
                "{} {}×{}×{} on {} ranks → {} ({}×{}, {} {}): frame {:.1} ms",
                node.name,
                node.dims[0],
                node.dims[1],
                node.dims[2],
                node.comm.n,
                cmd.output.display(),
                cam.size[0],
                cam.size[1],
                s.method.name(),
                s.mode.name(),
                frame_ms
            );
        }
    }
    Ok(())
}

/// `shearwarp rotate --distributed`: the frames of `rotate`, each rendered by
/// every rank; rank 0 times them and writes `--frames-dir`.
pub fn rotate(cmd: &RotateJob) -> Result<()> {
    check_args(cmd.render)?;
    if cmd.animation {
        usage!("--distributed writes --frames-dir; --gif and --apng are not available with it");
    }
    if !(cmd.degrees.is_finite() && cmd.degrees > 0.0) {
        usage!("--degrees must be a positive number, got {}", cmd.degrees);
    }
    let universe = init()?;
    let mut node = node_of(&universe, cmd.volume, cmd.render);
    let step = match cmd.step_deg {
        "auto" => one_bit_step_deg(node.dims) * cmd.render.cell.or(1) as f64,
        s => match s.parse::<f64>().ok().filter(|x| x.is_finite() && *x > 0.0) {
            Some(x) => x,
            None => usage!("--step-deg must be 'auto' or a positive number of degrees, got '{s}'"),
        },
    };
    let frames = ((cmd.degrees / step).round() as usize).max(1);
    if frames > 1_000_000 {
        usage!("{frames} frames is too many (raise --step-deg)");
    }
    let axis = cmd.axis;
    if node.comm.rank == 0
        && let Some(d) = cmd.frames_dir
    {
        let made = std::fs::create_dir_all(d).with_context(|| format!("{}: cannot create directory", d.display()));
        node.comm.agree(made);
    } else if cmd.frames_dir.is_some() {
        node.comm.agree(Ok(()));
    }
    let cam0 = node.camera;
    let n_tissues = node.renderer.tissues().map_or(1, |(t, _)| t.len());
    let mut tissue = node.renderer.tissues().map(|(_, c)| c);
    let size = cam0.map_or([1, 1], |c| c.size);
    let mut img = Image::new(size[0], size[1]);
    let mut records = Vec::with_capacity(frames);
    let mut wall = Vec::with_capacity(frames);
    for f in 0..frames {
        let cam = cam0.map(|c| Camera { rotation: rotate_eye(c.rotation, axis, f as f64 * step), ..c });
        if cmd.cycle_tissues > 0 && f > 0 && f % cmd.cycle_tissues == 0 {
            tissue = tissue.map(|t| (t + 1) % n_tissues);
        }
        let t = Instant::now();
        records.push(node.frame(cam, tissue, &mut img));
        wall.push(t.elapsed().as_secs_f64() * 1e3);
        if node.comm.rank == 0
            && let Some(d) = cmd.frames_dir
        {
            let w = shearwarp::output::write_png_unsynced(d.join(format!("frame_{f:05}.png")), &img.to_rgb8());
            node.comm.agree(w.map_err(anyhow::Error::from));
        } else if cmd.frames_dir.is_some() {
            node.comm.agree(Ok(()));
        }
    }
    if node.comm.rank == 0
        && let Some(d) = cmd.frames_dir
    {
        shearwarp::output::sync_written(d)?;
    }
    let ranks = node.ranks_json(&records);
    if let Some(ranks) = ranks {
        let mut w = wall.clone();
        w.sort_by(f64::total_cmp);
        let median = w[w.len() / 2];
        let s = node.renderer.settings();
        if cmd.json {
            let j = serde_json::json!({
                "volume": node.name, "dims": node.dims, "ranks": node.comm.n, "method": s.method.name(), "mode": s.mode.name(),
                "cell": s.cell, "size": size[0], "frames": frames, "step_deg": step, "frame_ms_median": median,
                "frames_per_second": 1e3 / median, "per_rank": ranks,
            });
            say!("{j}");
        } else {
            let bytes: u64 = records.iter().map(|r| r.received).sum::<u64>() / frames as u64;
            say!(
                "{} {}×{}×{} on {} ranks: {frames} frames, median {median:.2} ms a frame ({:.0} frames/s), rank 0 received {} a frame",
                node.name,
                node.dims[0],
                node.dims[1],
                node.dims[2],
                node.comm.n,
                1e3 / median,
                shearwarp::fmt::fmt_bytes(bytes)
            );
        }
    }
    Ok(())
}

/// Why a distributed frame does not run `v` (`None`: it does): the binary
/// and RLE paths, parallel, on the cartesian grid at quality 1, linear
/// reconstruction and no Deluxe option.
fn unsupported(v: &Variant) -> Option<&'static str> {
    let s = &v.settings;
    if !matches!(s.method, Method::Binary | Method::Rle) {
        Some("a distributed frame renders the binary and RLE paths only")
    } else if v.projection.is_perspective() {
        Some("a distributed frame renders parallel projections only")
    } else if v.quality != 1.0 {
        Some("a distributed frame renders at quality 1 only")
    } else if s.lattice != shearwarp::Lattice::Cartesian {
        Some("a distributed frame renders the cartesian grid only")
    } else if s.reconstruction != shearwarp::kernels::Reconstruction::Linear {
        Some("a distributed frame reconstructs linearly only")
    } else if !s.deluxe.is_standard() || s.rle_reuse {
        Some("a distributed frame takes no Deluxe option or encoding reuse")
    } else {
        None
    }
}

/// One variant's frames: rank 0's wall time of each and every rank's records.
struct Run {
    mode: Mode,
    name: String,
    wall: Vec<f64>,
    records: Vec<FrameRecord>,
}

/// `shearwarp bench --distributed`: the frame time of every binary and RLE
/// variant of the matrix over the benchmark's views, each frame rendered by
/// every rank and composited on rank 0; the other variants are listed as
/// skipped. Rank 0 prints the table (or `--json`) and writes `--json-out`.
pub fn bench(cmd: &BenchCmd) -> Result<()> {
    if cmd.suite.is_some() {
        usage!("--distributed times one volume; --suite is not available with it");
    }
    if !cmd.peers.is_empty() {
        usage!("--distributed does not run --peers");
    }
    if cmd.csv.is_some() || !cmd.plot.is_empty() || cmd.per_view {
        usage!(
            "--distributed measures frame times only: --csv, --plot and --per-view are not available with it (use --json or --json-out)"
        );
    }
    if !cmd.perspective.is_empty() || cmd.perspective_matrix {
        usage!("--distributed renders parallel projections only (drop --perspective and --perspective-matrix)");
    }
    cmd.check()?;
    shearwarp::render::checks::check_threads(cmd.threads)?;
    let mut modes = cmd.modes.clone();
    modes.dedup();
    let mut runs: Vec<(Mode, Vec<Variant>)> = vec![];
    let mut skipped = vec![];
    for &mode in &modes {
        let (ok, not): (Vec<Variant>, Vec<Variant>) = variants_of(cmd, mode).into_iter().partition(|v| unsupported(v).is_none());
        for v in &not {
            skipped.push(serde_json::json!({"mode": mode.name(), "variant": v.name, "reason": unsupported(v)}));
        }
        if !ok.is_empty() {
            runs.push((mode, ok));
        }
    }
    let Some(&(first_mode, _)) = runs.first() else {
        usage!("--distributed: --only {:?} matches no binary or RLE variant of the parallel matrix", cmd.only);
    };
    let universe = init()?;
    let size = [cmd.size, cmd.size];
    let mut node = Node::new(
        &universe,
        &cmd.volume,
        |_| Ok(Camera::new(glam::DMat3::IDENTITY, size)),
        |b| cmd.renderer(b, first_mode).map(|(r, _)| r),
    );
    let views = standard_views(NamedView::Anterior.rotation(), cmd.random_views, cmd.seed);
    let mut img = Image::new(cmd.size, cmd.size);
    let mut done: Vec<Run> = vec![];
    let mut classification = vec![];
    for (mode, variants) in &runs {
        if *mode != first_mode {
            // this mode's renderer of the same brick (as the bench makes one a mode)
            let r = node.renderer.volume().map(|v| v.into_owned()).map_err(anyhow::Error::from);
            let r = r.and_then(|v| cmd.renderer(v, *mode).map(|(r, _)| r));
            node.renderer = node.comm.agree(r);
        }
        classification.push(
            serde_json::json!({"mode": mode.name(), "classification": node.renderer.classification_name(), "iso": node.renderer.iso()}),
        );
        let tissue = node.renderer.tissues().map(|(_, c)| c);
        let first = done.len();
        done.extend(variants.iter().map(|v| Run { mode: *mode, name: v.name.clone(), wall: vec![], records: vec![] }));
        // rounds over the whole matrix of the mode: a change in load biases no variant
        for _ in 0..cmd.rounds {
            for (i, v) in variants.iter().enumerate() {
                let set = node.renderer.set_settings(Settings { threads: cmd.threads, ..v.settings });
                node.comm.agree(set.map_err(anyhow::Error::from));
                for view in &views {
                    let cam = Some(Camera { rotation: view.rotation, zoom: None, size }).filter(|_| node.comm.rank == 0);
                    for _ in 0..cmd.warmup {
                        node.frame(cam, tissue, &mut img);
                    }
                    for _ in 0..cmd.reps {
                        let t = Instant::now();
                        let rec = node.frame(cam, tissue, &mut img);
                        done[first + i].wall.push(t.elapsed().as_secs_f64() * 1e3);
                        done[first + i].records.push(rec);
                    }
                }
            }
        }
    }
    let mut rows = vec![];
    for run in &done {
        let ranks = node.ranks_json(&run.records);
        if let Some(ranks) = ranks {
            let mut w = run.wall.clone();
            let median = crate::app::median(&mut w).unwrap_or(f64::NAN);
            rows.push(serde_json::json!({
                "mode": run.mode.name(), "variant": run.name, "frames": run.wall.len(), "frame_ms_median": median,
                "frames_per_second": 1e3 / median, "per_rank": ranks,
            }));
        }
    }
    if node.comm.rank != 0 {
        return Ok(());
    }
    let j = serde_json::json!({
        "volume": node.name, "dims": node.dims, "spacing": node.spacing, "ranks": node.comm.n, "size": cmd.size,
        "threads": if cmd.threads == 0 { rayon::current_num_threads() } else { cmd.threads },
        "cpu": shearwarp::kernels::level().name(), "reps": cmd.reps, "rounds": cmd.rounds, "warmup": cmd.warmup,
        "views": views.iter().map(|v| v.name.clone()).collect::<Vec<_>>(), "classification": classification,
        "records": rows, "skipped": skipped,
    });
    if let Some(p) = &cmd.json_out {
        crate::app::output::write_text(p, &serde_json::to_string_pretty(&j)?)?;
    }
    if cmd.json {
        crate::app::output::print_text(&(serde_json::to_string_pretty(&j)? + "\n"))?;
    } else {
        crate::app::output::print_text(&bench_markdown(&j))?;
    }
    Ok(())
}

/// The distributed bench's table: a row per variant, rank 0's median frame
/// and the slowest rank's render, the bytes rank 0 received a frame.
fn bench_markdown(j: &serde_json::Value) -> String {
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let d = &j["dims"];
    let mut s = format!(
        "## {} ({}×{}×{}) on {} ranks, {}×{} pixels, {} views\n\n\
         | mode | variant | frame ms | frames/s | slowest rank render ms | rank 0 composite ms | rank 0 received a frame |\n\
         |---|---|---:|---:|---:|---:|---:|\n",
        j["volume"].as_str().unwrap_or(""),
        d[0],
        d[1],
        d[2],
        j["ranks"],
        j["size"],
        j["size"],
        j["views"].as_array().map_or(0, Vec::len)
    );
    for r in j["records"].as_array().into_iter().flatten() {
        let ranks = r["per_rank"].as_array().cloned().unwrap_or_default();
        let slowest = ranks.iter().map(|x| f(&x["render_ms"])).fold(0.0, f64::max);
        let r0 = ranks.first().cloned().unwrap_or_default();
        s += &format!(
            "| {} | {} | {:.2} | {:.1} | {:.2} | {:.2} | {} |\n",
            r["mode"].as_str().unwrap_or(""),
            r["variant"].as_str().unwrap_or(""),
            f(&r["frame_ms_median"]),
            f(&r["frames_per_second"]),
            slowest,
            f(&r0["composite_ms"]),
            shearwarp::fmt::fmt_bytes(f(&r0["received_bytes_per_frame"]) as u64)
        );
    }
    // the skipped variants, a line per reason
    let mut why: Vec<(&str, Vec<String>)> = vec![];
    for x in j["skipped"].as_array().into_iter().flatten() {
        let (r, name) =
            (x["reason"].as_str().unwrap_or(""), format!("{} {}", x["mode"].as_str().unwrap_or(""), x["variant"].as_str().unwrap_or("")));
        match why.iter_mut().find(|(w, _)| *w == r) {
            Some((_, names)) => names.push(name),
            None => why.push((r, vec![name])),
        }
    }
    if !why.is_empty() {
        s += "\nSkipped:\n";
        for (r, names) in &why {
            s += &format!("- {r}: {}\n", names.join(", "));
        }
    }
    s
}
