/*
 * harness.c -- VolPack reference harness for the shearwarp crate.
 *
 * Renders a rotation sequence with VolPack's run-length-encoded shear-warp
 * (vpRenderClassifiedVolume, Lacroute & Levoy 1994) and prints one JSON
 * object with per-frame timings, so our Rust renderer can be compared side
 * by side on exactly the same volume, classification, shading and views.
 *
 * Build:  cc -O2 -o harness harness.c -lvolpack -lm
 * Usage:  harness --help
 *
 * Everything the Rust side needs to match (threshold, opacity ramps, light,
 * material, window, orientation) is echoed in the JSON output and described
 * in benches/scripts/volpack/README.md.
 */

#define _POSIX_C_SOURCE 200809L
#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <volpack.h>

/* ------------------------------------------------------------------ */
/* voxel layout: shading needs only the encoded normal; classification */
/* uses only the density (scalar-only opacity, no gradient-magnitude   */
/* factor).  The gradient byte is filled by vpVolumeNormals but unused. */

typedef struct {
    short normal;          /* field 0: encoded surface normal (VP_NORM_MAX) */
    unsigned char density; /* field 1: 8-bit scalar */
    unsigned char gradient;/* field 2: gradient magnitude (unused) */
} Voxel;

#define NORMAL_FIELD 0
#define DENSITY_FIELD 1
#define GRADIENT_FIELD 2
#define VOXEL_FIELDS 3
#define SHADE_FIELDS 1   /* only the normal is kept in the classified volume */
#define CLSFY_FIELDS 1   /* one classification parameter: density */
#define DENSITY_PARAM 0

/* ------------------------------------------------------------------ */
/* material / light: Blinn-Phong, one white headlight                  */

#define MAT_AMBIENT 0.10
#define MAT_DIFFUSE 0.60
#define MAT_SPECULAR 0.30
#define MAT_SHININESS 20.0

/* ------------------------------------------------------------------ */

static void die(const char *fmt, const char *arg)
{
    fprintf(stderr, "harness: ");
    fprintf(stderr, fmt, arg);
    fprintf(stderr, "\n");
    exit(2);
}

static void vpcheck(vpContext *vpc, vpResult r, const char *what)
{
    if (r != VP_OK) {
        fprintf(stderr, "harness: VolPack error in %s: %s\n", what,
                vpGetErrorString(vpGetError(vpc)));
        exit(1);
    }
}

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* median of a sorted array */
static double median_sorted(const double *v, int n)
{
    if (n <= 0)
        return 0.0;
    if (n % 2)
        return v[n / 2];
    return 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* nearest-rank percentile of a sorted array, p in (0,100] */
static double percentile_sorted(const double *v, int n, double p)
{
    int k;
    if (n <= 0)
        return 0.0;
    k = (int)ceil(p / 100.0 * n) - 1;
    if (k < 0)
        k = 0;
    if (k >= n)
        k = n - 1;
    return v[k];
}

/* ------------------------------------------------------------------ */
/* input volumes                                                       */

static uint16_t rd16(const unsigned char *p, int swap)
{
    return swap ? (uint16_t)((p[0] << 8) | p[1]) : (uint16_t)(p[0] | (p[1] << 8));
}

static uint32_t rd32(const unsigned char *p, int swap)
{
    return swap ? ((uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 |
                   (uint32_t)p[2] << 8 | p[3])
                : ((uint32_t)p[3] << 24 | (uint32_t)p[2] << 16 |
                   (uint32_t)p[1] << 8 | p[0]);
}

static unsigned char *read_file(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    unsigned char *buf;
    long n;
    if (!f)
        die("cannot open %s", path);
    if (fseek(f, 0, SEEK_END) != 0 || (n = ftell(f)) < 0)
        die("cannot seek %s", path);
    rewind(f);
    buf = malloc(n > 0 ? (size_t)n : 1);
    if (!buf)
        die("out of memory reading %s", path);
    if (fread(buf, 1, (size_t)n, f) != (size_t)n)
        die("short read on %s", path);
    fclose(f);
    *len = (size_t)n;
    return buf;
}

/*
 * .den file (VolPack / SoftLab): 62-byte header of 16-bit shorts
 *   map_version(1) orig_min[3] orig_max[3] orig_len[3] extr_min[3]
 *   extr_max[3] extr_len[3] map_min[3] map_max[3] map_len[3] map_warps(1)
 * then a 32-bit map_length, then map_len[0]*map_len[1]*map_len[2] bytes,
 * x fastest.  map_version is 1; 0x0100 means the header is byte-swapped.
 */
#define DEN_HEADER 62

static unsigned char *load_den(const char *path, int dims[3])
{
    size_t len;
    unsigned char *buf = read_file(path, &len), *vox;
    int swap, i;
    uint32_t n;
    if (len < DEN_HEADER)
        die("%s: too short for a .den file", path);
    if (rd16(buf, 0) == 1)
        swap = 0;
    else if (rd16(buf, 0) == 0x0100)
        swap = 1;
    else
        die("%s: not a .den file (bad map_version)", path);
    for (i = 0; i < 3; i++)
        dims[i] = (int16_t)rd16(buf + 2 + 2 * (3 * 8 + i), swap); /* map_len */
    n = rd32(buf + 58, swap);
    if (dims[0] <= 0 || dims[1] <= 0 || dims[2] <= 0 ||
        (uint64_t)dims[0] * dims[1] * dims[2] != n)
        die("%s: inconsistent .den header", path);
    if (len < DEN_HEADER + (size_t)n)
        die("%s: truncated .den data", path);
    vox = malloc(n);
    if (!vox)
        die("out of memory for %s", path);
    memcpy(vox, buf + DEN_HEADER, n);
    free(buf);
    return vox;
}

static void wr16(FILE *f, int v)
{
    unsigned char b[2] = {(unsigned char)(v & 0xff), (unsigned char)((v >> 8) & 0xff)};
    fwrite(b, 1, 2, f);
}

static void write_den(const char *path, const unsigned char *v, const int d[3])
{
    FILE *f = fopen(path, "wb");
    uint32_t n = (uint32_t)d[0] * d[1] * d[2];
    unsigned char b[4];
    int k, i;
    if (!f)
        die("cannot create %s", path);
    wr16(f, 1); /* map_version */
    /* orig, extr and map: min = 0, max = len - 1, len */
    for (k = 0; k < 3; k++) {
        for (i = 0; i < 3; i++) wr16(f, 0);
        for (i = 0; i < 3; i++) wr16(f, d[i] - 1);
        for (i = 0; i < 3; i++) wr16(f, d[i]);
    }
    wr16(f, 0); /* map_warps */
    b[0] = n & 0xff; b[1] = (n >> 8) & 0xff; b[2] = (n >> 16) & 0xff; b[3] = n >> 24;
    fwrite(b, 1, 4, f);
    if (fwrite(v, 1, n, f) != n || fclose(f) != 0)
        die("write failed on %s", path);
}

static unsigned char *load_raw(const char *path, const int d[3])
{
    size_t len, n = (size_t)d[0] * d[1] * d[2];
    unsigned char *buf = read_file(path, &len);
    if (len != n) {
        fprintf(stderr, "harness: %s has %zu bytes, --raw dims need %zu\n",
                path, len, n);
        exit(2);
    }
    return buf;
}

/*
 * Sphere test volume: N^3 u8, centre c = (N-1)/2 in voxel-index coordinates,
 * radius R = 0.4 N.  value = 200 for r <= R-2, 0 for r >= R+2, and a linear
 * ramp 200*(R+2-r)/4 in between (4 voxels wide, centred on the surface),
 * rounded to nearest.
 */
static unsigned char *make_sphere(int n, int d[3])
{
    unsigned char *v = malloc((size_t)n * n * n);
    double c = 0.5 * (n - 1), R = 0.4 * n;
    int x, y, z;
    if (!v)
        die("out of memory for sphere %s", "");
    for (z = 0; z < n; z++)
        for (y = 0; y < n; y++)
            for (x = 0; x < n; x++) {
                double r = sqrt((x - c) * (x - c) + (y - c) * (y - c) +
                                (z - c) * (z - c));
                double val;
                if (r <= R - 2.0)
                    val = 200.0;
                else if (r >= R + 2.0)
                    val = 0.0;
                else
                    val = 200.0 * (R + 2.0 - r) / 4.0;
                v[((size_t)z * n + y) * n + x] = (unsigned char)(val + 0.5);
            }
    d[0] = d[1] = d[2] = n;
    return v;
}

/*
 * Trilinear upsampling by an integer factor f per axis: output voxel o maps
 * to input coordinate o / f (so every f-th output voxel is an input voxel and
 * the others are trilinear blends), clamped to the last input voxel; the
 * result is rounded to nearest.  128x128x84 -> 256x256x168 for f = 2.
 */
static unsigned char *upsample(const unsigned char *in, const int d[3], int f,
                               int od[3])
{
    int x, y, z, i;
    unsigned char *out;
    int *x0, *x1;
    float *xw;
    for (i = 0; i < 3; i++)
        od[i] = d[i] * f;
    out = malloc((size_t)od[0] * od[1] * od[2]);
    x0 = malloc(sizeof(int) * od[0]);
    x1 = malloc(sizeof(int) * od[0]);
    xw = malloc(sizeof(float) * od[0]);
    if (!out || !x0 || !x1 || !xw)
        die("out of memory upsampling %s", "");
    for (x = 0; x < od[0]; x++) {
        double p = (double)x / f;
        int a = (int)floor(p);
        if (a >= d[0] - 1) { a = d[0] - 1; p = a; }
        x0[x] = a;
        x1[x] = a + 1 < d[0] ? a + 1 : a;
        xw[x] = (float)(p - a);
    }
    for (z = 0; z < od[2]; z++) {
        double pz = (double)z / f;
        int z0 = (int)floor(pz), z1;
        float wz;
        if (z0 >= d[2] - 1) { z0 = d[2] - 1; pz = z0; }
        z1 = z0 + 1 < d[2] ? z0 + 1 : z0;
        wz = (float)(pz - z0);
        for (y = 0; y < od[1]; y++) {
            double py = (double)y / f;
            int y0 = (int)floor(py), y1;
            float wy;
            const unsigned char *r00, *r01, *r10, *r11;
            if (y0 >= d[1] - 1) { y0 = d[1] - 1; py = y0; }
            y1 = y0 + 1 < d[1] ? y0 + 1 : y0;
            wy = (float)(py - y0);
            r00 = in + ((size_t)z0 * d[1] + y0) * d[0];
            r01 = in + ((size_t)z0 * d[1] + y1) * d[0];
            r10 = in + ((size_t)z1 * d[1] + y0) * d[0];
            r11 = in + ((size_t)z1 * d[1] + y1) * d[0];
            for (x = 0; x < od[0]; x++) {
                int a = x0[x], b = x1[x];
                float wx = xw[x];
                float c00 = r00[a] + wx * (r00[b] - r00[a]);
                float c01 = r01[a] + wx * (r01[b] - r01[a]);
                float c10 = r10[a] + wx * (r10[b] - r10[a]);
                float c11 = r11[a] + wx * (r11[b] - r11[a]);
                float c0 = c00 + wy * (c01 - c00);
                float c1 = c10 + wy * (c11 - c10);
                float c = c0 + wz * (c1 - c0);
                out[((size_t)z * od[1] + y) * od[0] + x] =
                    (unsigned char)(c + 0.5f);
            }
        }
    }
    free(x0);
    free(x1);
    free(xw);
    return out;
}

static void write_pgm(const char *path, const unsigned char *img, int w, int h)
{
    FILE *f = fopen(path, "wb");
    if (!f)
        die("cannot create %s", path);
    fprintf(f, "P5\n%d %d\n255\n", w, h);
    if (fwrite(img, 1, (size_t)w * h, f) != (size_t)w * h || fclose(f) != 0)
        die("write failed on %s", path);
}

/* ------------------------------------------------------------------ */

static void usage(FILE *f)
{
    fprintf(f,
"usage: harness [input] [options]\n"
"input (one of):\n"
"  --den FILE            VolPack .den volume (u8)\n"
"  --raw X,Y,Z FILE      raw u8 volume, x fastest\n"
"  --sphere N            synthetic N^3 sphere (200 inside r=0.4N, 4-voxel ramp)\n"
"options:\n"
"  --upsample F          trilinear F-times upsampling per axis (F=2: 128x128x84 -> 256x256x168)\n"
"  --name NAME           volume name for the JSON (default: file stem / sphereN)\n"
"  --tf opaque|ramp      classification (default opaque)\n"
"                          opaque: alpha = clamp((d - T)/4, 0, 1)\n"
"                          ramp:   alpha = A * clamp((d - T)/(E - T), 0, 1)\n"
"  --threshold T         density threshold T (default 24)\n"
"  --ramp-top A          ramp: opacity reached at density E (default 0.3)\n"
"  --ramp-end E          ramp: density where the ramp tops out (default 255)\n"
"  --min-opacity V       VP_MIN_VOXEL_OPACITY (default 0.05; voxels <= V are dropped)\n"
"  --max-ray-opacity V   VP_MAX_RAY_OPACITY, early ray termination (default 0.95)\n"
"  --size N              image N x N (default 512; VolPack's examples use 256)\n"
"  --fit diag|maxdim     zoom: volume bounding diagonal = image width (default),\n"
"                        or VolPack's default window (largest dimension = image width)\n"
"  --frames N            frames to render (default 360)\n"
"  --step-deg D          rotation step about VP_Y_AXIS per frame (default 1)\n"
"  --warmup N            untimed frames rendered before timing (default 1)\n"
"  --frames-out DIR      write frames listed by --save-frames as PGM into DIR\n"
"  --save-frames LIST    comma-separated frame indices (default 0,45)\n"
"  --write-den FILE      write the (generated/upsampled) input volume as .den\n"
"                        (with --frames 0: write it and exit, no VolPack work)\n"
"  --times               also print every frame time in the JSON\n"
"shearwarp's matched views (`shearwarp bench --peers volpack`):\n"
"  --views FILE          one view per line: NAME m00 m01 m02 m10 m11 m12 m20 m21 m22,\n"
"                        the volume's rotation (row-major) about its voxel-centre\n"
"                        (dims-1)/2; each rendered --warmup + --reps times and\n"
"                        saved as DIR/NAME.pgm with --frames-out DIR (replaces\n"
"                        --frames, --step-deg, --fit, --save-frames); needs --zoom\n"
"  --zoom Z              image pixels per voxel; pixel (c, r) samples\n"
"                        ((c - (N-1)/2)/Z, (r - (N-1)/2)/Z), as shearwarp's do\n"
"  --reps R              timed renders per view (default 3)\n");
}

#define MAX_VIEWS 4096

/* shearwarp's matched views: names and row-major rotations */
typedef struct {
    char name[128];
    double m[9];
} MatchedView;

static int load_views(const char *path, MatchedView *v)
{
    FILE *f = fopen(path, "r");
    char line[1024];
    int n = 0, ln = 0;
    if (!f) die("cannot read --views %s", path);
    while (fgets(line, sizeof line, f)) {
        MatchedView *w = &v[n];
        int k, got;
        ln++;
        if (strspn(line, " \t\r\n") == strlen(line)) continue;
        if (n == MAX_VIEWS) die("--views: more than 4096 views%s", "");
        got = sscanf(line, "%127s %lf %lf %lf %lf %lf %lf %lf %lf %lf", w->name, &w->m[0], &w->m[1],
                     &w->m[2], &w->m[3], &w->m[4], &w->m[5], &w->m[6], &w->m[7], &w->m[8]);
        if (got != 10) {
            fprintf(stderr, "harness: --views %s line %d: ", path, ln);
            die("expected NAME and 9 numbers%s", "");
        }
        for (k = 0; k < 9; k++)
            if (!isfinite(w->m[k])) die("--views: a matrix entry is not finite%s", "");
        for (k = 0; w->name[k]; k++)
            if (!isalnum((unsigned char)w->name[k]) && !strchr("._+-", w->name[k]))
                die("--views: view names may hold letters, digits and ._+- only%s", "");
        n++;
    }
    fclose(f);
    if (n == 0) die("--views %s holds no view", path);
    return n;
}

/* One frame of the current view: the shade table (timed apart, excluded from
   frame_ms) and vpRenderClassifiedVolume (compositing and warp). */
static void render_frame(vpContext *vpc, double *shade_ms, double *render_ms)
{
    double s0 = now_ms();
    vpcheck(vpc, vpShadeTable(vpc), "vpShadeTable");
    double s1 = now_ms();
    vpcheck(vpc, vpRenderClassifiedVolume(vpc), "vpRenderClassifiedVolume");
    *shade_ms = s1 - s0;
    *render_ms = now_ms() - s1;
}

static int parse_int(const char *s, const char *opt)
{
    char *end;
    long v;
    errno = 0;
    v = strtol(s, &end, 10);
    if (errno || *end || end == s)
        die("bad integer for %s", opt);
    return (int)v;
}

static double parse_double(const char *s, const char *opt)
{
    char *end;
    double v;
    errno = 0;
    v = strtod(s, &end);
    if (errno || *end || end == s)
        die("bad number for %s", opt);
    return v;
}

int main(int argc, char **argv)
{
    const char *den_path = NULL, *raw_path = NULL, *name = NULL;
    const char *tf = "opaque", *fit = "diag", *frames_out = NULL;
    const char *save_list = "0,45", *write_den_path = NULL;
    int raw_dims[3] = {0, 0, 0}, sphere_n = 0, up = 1;
    int size = 512, frames = 360, warmup = 1, print_times = 0;
    double threshold = 24.0, ramp_top = 0.3, ramp_end = 255.0;
    double min_opacity = 0.05, max_ray_opacity = 0.95, step_deg = 1.0;
    const char *views_path = NULL;
    double zoom = 0.0;
    int reps = 3, nviews = 0;
    static MatchedView views[MAX_VIEWS];

    int dims[3];
    unsigned char *scalars;
    char vname[256];
    int i;

    for (i = 1; i < argc; i++) {
        const char *a = argv[i];
#define NEXT() (i + 1 < argc ? argv[++i] : (die("missing value for %s", a), ""))
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            usage(stdout);
            return 0;
        } else if (!strcmp(a, "--den")) den_path = NEXT();
        else if (!strcmp(a, "--raw")) {
            const char *d = NEXT();
            if (sscanf(d, "%d,%d,%d", &raw_dims[0], &raw_dims[1], &raw_dims[2]) != 3)
                die("--raw needs X,Y,Z, got %s", d);
            raw_path = NEXT();
        }
        else if (!strcmp(a, "--sphere")) sphere_n = parse_int(NEXT(), a);
        else if (!strcmp(a, "--upsample")) up = parse_int(NEXT(), a);
        else if (!strcmp(a, "--name")) name = NEXT();
        else if (!strcmp(a, "--tf")) tf = NEXT();
        else if (!strcmp(a, "--threshold")) threshold = parse_double(NEXT(), a);
        else if (!strcmp(a, "--ramp-top")) ramp_top = parse_double(NEXT(), a);
        else if (!strcmp(a, "--ramp-end")) ramp_end = parse_double(NEXT(), a);
        else if (!strcmp(a, "--min-opacity")) min_opacity = parse_double(NEXT(), a);
        else if (!strcmp(a, "--max-ray-opacity")) max_ray_opacity = parse_double(NEXT(), a);
        else if (!strcmp(a, "--size")) size = parse_int(NEXT(), a);
        else if (!strcmp(a, "--fit")) fit = NEXT();
        else if (!strcmp(a, "--frames")) frames = parse_int(NEXT(), a);
        else if (!strcmp(a, "--step-deg")) step_deg = parse_double(NEXT(), a);
        else if (!strcmp(a, "--warmup")) warmup = parse_int(NEXT(), a);
        else if (!strcmp(a, "--frames-out")) frames_out = NEXT();
        else if (!strcmp(a, "--save-frames")) save_list = NEXT();
        else if (!strcmp(a, "--write-den")) write_den_path = NEXT();
        else if (!strcmp(a, "--times")) print_times = 1;
        else if (!strcmp(a, "--views")) views_path = NEXT();
        else if (!strcmp(a, "--zoom")) zoom = parse_double(NEXT(), a);
        else if (!strcmp(a, "--reps")) reps = parse_int(NEXT(), a);
        else {
            usage(stderr);
            die("unknown option %s", a);
        }
#undef NEXT
    }
    if (!!den_path + !!raw_path + !!sphere_n != 1) {
        usage(stderr);
        die("give exactly one of --den, --raw, --sphere%s", "");
    }
    if (strcmp(tf, "opaque") && strcmp(tf, "ramp"))
        die("--tf must be opaque or ramp, got %s", tf);
    if (strcmp(fit, "diag") && strcmp(fit, "maxdim"))
        die("--fit must be diag or maxdim, got %s", fit);
    if (size < 1 || size > 16384) die("bad --size%s", "");
    if (frames < 0 || warmup < 0) die("bad --frames/--warmup%s", "");
    if (up < 1 || up > 8) die("bad --upsample%s", "");
    if (!strcmp(tf, "ramp") && !(ramp_end > threshold))
        die("--ramp-end must exceed --threshold%s", "");
    if (views_path) {
        if (!(zoom > 0.0 && isfinite(zoom))) die("--views needs --zoom Z (finite, > 0)%s", "");
        if (reps < 1 || reps > 100000) die("bad --reps%s", "");
        nviews = load_views(views_path, views);
        frames = nviews * reps; /* the timing arrays hold every timed render */
    }

    /* ---- load / generate the volume ---- */
    if (den_path) {
        const char *base = strrchr(den_path, '/');
        size_t n;
        scalars = load_den(den_path, dims);
        base = base ? base + 1 : den_path;
        n = strcspn(base, ".");
        snprintf(vname, sizeof vname, "%.*s", (int)n, base);
    } else if (raw_path) {
        const char *base = strrchr(raw_path, '/');
        size_t n;
        memcpy(dims, raw_dims, sizeof dims);
        scalars = load_raw(raw_path, dims);
        base = base ? base + 1 : raw_path;
        n = strcspn(base, ".");
        snprintf(vname, sizeof vname, "%.*s", (int)n, base);
    } else {
        scalars = make_sphere(sphere_n, dims);
        snprintf(vname, sizeof vname, "sphere%d", sphere_n);
    }
    if (up > 1) {
        int od[3];
        unsigned char *u = upsample(scalars, dims, up, od);
        free(scalars);
        scalars = u;
        memcpy(dims, od, sizeof dims);
        snprintf(vname + strlen(vname), sizeof vname - strlen(vname), "-up%d", up);
    }
    if (name)
        snprintf(vname, sizeof vname, "%s", name);
    if (write_den_path) {
        write_den(write_den_path, scalars, dims);
        if (frames == 0) /* only the volume file was wanted */
            return 0;
    }

    /* ---- VolPack context, voxel layout ---- */
    vpContext *vpc = vpCreateContext();
    size_t nvox = (size_t)dims[0] * dims[1] * dims[2];
    Voxel *dummy_voxel = NULL;
    Voxel *voxels = malloc(nvox * sizeof(Voxel));
    static float density_table[VP_SCALAR_MAX + 1];
    static float shade_table[VP_NORM_MAX + 1];
    if (!voxels)
        die("out of memory for the voxel array%s", "");
    (void)dummy_voxel;

    vpcheck(vpc, vpSetVolumeSize(vpc, dims[0], dims[1], dims[2]), "vpSetVolumeSize");
    vpcheck(vpc, vpSetVoxelSize(vpc, sizeof(Voxel), VOXEL_FIELDS, SHADE_FIELDS,
                                CLSFY_FIELDS), "vpSetVoxelSize");
    vpcheck(vpc, vpSetVoxelField(vpc, NORMAL_FIELD, sizeof(short),
                                 vpFieldOffset(dummy_voxel, normal), VP_NORM_MAX),
            "vpSetVoxelField(normal)");
    vpcheck(vpc, vpSetVoxelField(vpc, DENSITY_FIELD, sizeof(unsigned char),
                                 vpFieldOffset(dummy_voxel, density), VP_SCALAR_MAX),
            "vpSetVoxelField(density)");
    vpcheck(vpc, vpSetVoxelField(vpc, GRADIENT_FIELD, sizeof(unsigned char),
                                 vpFieldOffset(dummy_voxel, gradient), VP_GRAD_MAX),
            "vpSetVoxelField(gradient)");
    vpcheck(vpc, vpSetRawVoxels(vpc, voxels, (int)(nvox * sizeof(Voxel)),
                                sizeof(Voxel), dims[0] * sizeof(Voxel),
                                dims[0] * dims[1] * sizeof(Voxel)),
            "vpSetRawVoxels");

    /* ---- scalar-only opacity transfer function ---- */
    for (i = 0; i <= VP_SCALAR_MAX; i++) {
        double a;
        if (!strcmp(tf, "opaque"))
            a = (i - threshold) / 4.0;
        else
            a = ramp_top * (i - threshold) / (ramp_end - threshold);
        if (a < 0.0) a = 0.0;
        if (!strcmp(tf, "opaque")) { if (a > 1.0) a = 1.0; }
        else if (a > ramp_top) a = ramp_top;
        density_table[i] = (float)a;
    }
    vpcheck(vpc, vpSetClassifierTable(vpc, DENSITY_PARAM, DENSITY_FIELD,
                                      density_table, sizeof(density_table)),
            "vpSetClassifierTable");
    vpcheck(vpc, vpSetd(vpc, VP_MIN_VOXEL_OPACITY, min_opacity), "VP_MIN_VOXEL_OPACITY");

    /* ---- preprocessing (untimed for frames): normals + RLE classification ---- */
    double t0 = now_ms();
    vpcheck(vpc, vpVolumeNormals(vpc, scalars, (int)nvox, DENSITY_FIELD,
                                 GRADIENT_FIELD, NORMAL_FIELD), "vpVolumeNormals");
    double t1 = now_ms();
    vpcheck(vpc, vpClassifyVolume(vpc), "vpClassifyVolume");
    double t2 = now_ms();
    double normals_ms = t1 - t0, classify_ms = t2 - t1;
    int rle_bytes[3] = {0, 0, 0};
    vpGeti(vpc, VP_VIEW_X_SIZE, &rle_bytes[0]);
    vpGeti(vpc, VP_VIEW_Y_SIZE, &rle_bytes[1]);
    vpGeti(vpc, VP_VIEW_Z_SIZE, &rle_bytes[2]);
    /* the raw voxel array is no longer needed for vpRenderClassifiedVolume */
    vpSetRawVoxels(vpc, NULL, 0, 0, 0, 0);
    free(voxels);

    /* ---- shading: one material, lookup shader, white headlight ---- */
    vpcheck(vpc, vpSetLookupShader(vpc, 1, 1, NORMAL_FIELD, shade_table,
                                   sizeof(shade_table), 0, NULL, 0),
            "vpSetLookupShader");
    vpcheck(vpc, vpSetMaterial(vpc, VP_MATERIAL0, VP_AMBIENT, VP_BOTH_SIDES,
                               MAT_AMBIENT, MAT_AMBIENT, MAT_AMBIENT), "ambient");
    vpcheck(vpc, vpSetMaterial(vpc, VP_MATERIAL0, VP_DIFFUSE, VP_BOTH_SIDES,
                               MAT_DIFFUSE, MAT_DIFFUSE, MAT_DIFFUSE), "diffuse");
    vpcheck(vpc, vpSetMaterial(vpc, VP_MATERIAL0, VP_SPECULAR, VP_BOTH_SIDES,
                               MAT_SPECULAR, MAT_SPECULAR, MAT_SPECULAR), "specular");
    vpcheck(vpc, vpSetMaterial(vpc, VP_MATERIAL0, VP_SHINYNESS, VP_BOTH_SIDES,
                               MAT_SHININESS, 0.0, 0.0), "shininess");
    /* The model matrix is the identity here, so the light vector is stored in
       world (= eye) coordinates and stays fixed while the model rotates: a
       headlight.  vpShadeTable uses it as the vector towards the light
       (n.l, h = normalize(l + v) with v = (0,0,1) towards the viewer), so
       (0,0,1) lights the surfaces facing the viewer. */
    vpcheck(vpc, vpSetLight(vpc, VP_LIGHT0, VP_DIRECTION, 0.0, 0.0, 1.0), "light dir");
    vpcheck(vpc, vpSetLight(vpc, VP_LIGHT0, VP_COLOR, 1.0, 1.0, 1.0), "light color");
    vpcheck(vpc, vpEnable(vpc, VP_LIGHT0, 1), "enable light");
    vpcheck(vpc, vpEnable(vpc, VP_DEPTH_CUE, 0), "depth cue off");

    /* ---- projection: orthographic window ---- */
    int maxdim = dims[0];
    if (dims[1] > maxdim) maxdim = dims[1];
    if (dims[2] > maxdim) maxdim = dims[2];
    double diag = sqrt((double)dims[0] * dims[0] + (double)dims[1] * dims[1] +
                       (double)dims[2] * dims[2]);
    /* VolPack object space: the volume is scaled by 1/maxdim (isotropic) and
       centred, so the largest dimension spans [-0.5, 0.5].  A window of
       half-width h maps [-h, h] onto the N image pixels. */
    double half = !strcmp(fit, "diag") ? 0.5 * diag / maxdim : 0.5;
    if (views_path) /* Z pixels per voxel: the window spans N/Z voxels */
        half = size / (2.0 * zoom * maxdim);
    double px_per_voxel = size / (2.0 * half * maxdim);
    vpcheck(vpc, vpCurrentMatrix(vpc, VP_PROJECT), "vpCurrentMatrix(PROJECT)");
    vpcheck(vpc, vpIdentityMatrix(vpc), "vpIdentityMatrix(PROJECT)");
    vpcheck(vpc, vpWindow(vpc, VP_PARALLEL, -half, half, -half, half, -half, half),
            "vpWindow");
    vpcheck(vpc, vpCurrentMatrix(vpc, VP_MODEL), "vpCurrentMatrix(MODEL)");
    vpcheck(vpc, vpSeti(vpc, VP_CONCAT_MODE, VP_CONCAT_LEFT), "VP_CONCAT_MODE");

    /* ---- image ---- */
    unsigned char *image = malloc((size_t)size * size);
    if (!image) die("out of memory for the image%s", "");
    memset(image, 0, (size_t)size * size);
    vpcheck(vpc, vpSetImage(vpc, image, size, size, size, VP_LUMINANCE), "vpSetImage");
    vpcheck(vpc, vpSetd(vpc, VP_MAX_RAY_OPACITY, max_ray_opacity), "VP_MAX_RAY_OPACITY");
    /* the intermediate image is at voxel resolution: at most 2*maxdim per side */
    vpSeti(vpc, VP_INT_WIDTH_HINT, 2 * maxdim + 2);
    vpSeti(vpc, VP_INT_HEIGHT_HINT, 2 * maxdim + 2);

    /* ---- frames ---- */
    double *render_ms = malloc(sizeof(double) * (frames > 0 ? frames : 1));
    double *shade_ms = malloc(sizeof(double) * (frames > 0 ? frames : 1));
    int *save = calloc((size_t)(frames > 0 ? frames : 1), sizeof(int));
    if (!render_ms || !shade_ms || !save) die("out of memory%s", "");
    if (frames_out) {
        const char *p = save_list;
        while (*p) {
            char *end;
            long k = strtol(p, &end, 10);
            if (end == p) die("bad --save-frames %s", save_list);
            if (k >= 0 && k < frames) save[k] = 1;
            p = *end == ',' ? end + 1 : end;
            if (*end && *end != ',') die("bad --save-frames %s", save_list);
        }
    }

    int nimg = 0;
    /* shearwarp's matched views. VolPack maps voxel p to column
       N/2 + s*x', row N/2 + s*y' with (x', y') of M (p - dims/2) and s = Z
       here; shearwarp puts it at (N-1)/2 + Z*x' with x' of M (p - (dims-1)/2).
       The model matrix [M | t] (object units: voxels / maxdim) with
       t = (Z*(M h) - 1/2) / (Z*maxdim), h = (1/2, 1/2, 1/2), on x and y makes
       the two agree (z only orders the slices). */
    for (int vi = 0; vi < nviews; vi++) {
        const double *m = views[vi].m;
        double S = zoom * maxdim;
        vpMatrix4 mm;
        int r, k;
        for (r = 0; r < 4; r++)
            for (k = 0; k < 4; k++) mm[r][k] = (r == k && r == 3) ? 1.0 : 0.0;
        for (r = 0; r < 3; r++) {
            for (k = 0; k < 3; k++) mm[r][k] = m[3 * r + k];
            if (r < 2)
                mm[r][3] = (zoom * 0.5 * (m[3 * r] + m[3 * r + 1] + m[3 * r + 2]) - 0.5) / S;
        }
        vpcheck(vpc, vpIdentityMatrix(vpc), "vpIdentityMatrix(MODEL)");
        vpcheck(vpc, vpSetMatrix(vpc, mm), "vpSetMatrix(MODEL)");
        for (i = -warmup; i < reps; i++) {
            double sh, re;
            render_frame(vpc, &sh, &re);
            if (i < 0)
                continue;
            shade_ms[vi * reps + i] = sh;
            render_ms[vi * reps + i] = re;
        }
        if (frames_out) {
            char path[4096];
            snprintf(path, sizeof path, "%s/%s.pgm", frames_out, views[vi].name);
            write_pgm(path, image, size, size);
            nimg++;
        }
    }
    for (i = -warmup; i < (views_path ? 0 : frames); i++) {
        int f = i < 0 ? 0 : i;
        /* view of frame f: model = R_y(f * step) (VolPack's vpRotate matrix),
           set from scratch each frame so no rounding accumulates. */
        vpcheck(vpc, vpIdentityMatrix(vpc), "vpIdentityMatrix(MODEL)");
        vpcheck(vpc, vpRotate(vpc, VP_Y_AXIS, f * step_deg), "vpRotate");
        double sh, re;
        render_frame(vpc, &sh, &re);
        if (i < 0)
            continue;
        shade_ms[i] = sh;
        render_ms[i] = re;
        if (frames_out && save[i]) {
            char path[4096];
            snprintf(path, sizeof path, "%s/volpack_%s_%s_%d_f%03d.pgm", frames_out,
                     vname, tf, size, i);
            write_pgm(path, image, size, size);
            nimg++;
        }
    }

    /* ---- statistics ---- */
    double *sorted = malloc(sizeof(double) * (frames > 0 ? frames : 1));
    double *ssorted = malloc(sizeof(double) * (frames > 0 ? frames : 1));
    double mean = 0.0, total = 0.0;
    memcpy(sorted, render_ms, sizeof(double) * frames);
    memcpy(ssorted, shade_ms, sizeof(double) * frames);
    qsort(sorted, frames, sizeof(double), cmp_double);
    qsort(ssorted, frames, sizeof(double), cmp_double);
    for (i = 0; i < frames; i++) total += render_ms[i];
    if (frames) mean = total / frames;

    /* ---- JSON ---- */
    printf("{\"renderer\":\"volpack\",\"volume\":\"%s\",\"dims\":[%d,%d,%d],"
           "\"size\":%d,\"tf\":\"%s\",\"frames\":%d,",
           vname, dims[0], dims[1], dims[2], size, tf, frames);
    printf("\"preprocess_ms\":%.3f,\"frame_ms_median\":%.4f,\"frame_ms_mean\":%.4f,"
           "\"frame_ms_p90\":%.4f,\"frame_ms_min\":%.4f,\"frame_ms_max\":%.4f,",
           normals_ms + classify_ms, median_sorted(sorted, frames), mean,
           percentile_sorted(sorted, frames, 90.0), frames ? sorted[0] : 0.0,
           frames ? sorted[frames - 1] : 0.0);
    printf("\"normals_ms\":%.3f,\"classify_ms\":%.3f,\"shade_table_ms_median\":%.4f,"
           "\"rle_bytes\":[%d,%d,%d],",
           normals_ms, classify_ms, median_sorted(ssorted, frames),
           rle_bytes[0], rle_bytes[1], rle_bytes[2]);
    if (!strcmp(tf, "opaque"))
        printf("\"tf_params\":{\"kind\":\"opaque\",\"threshold\":%g,\"ramp_width\":4,"
               "\"opacity\":\"clamp((d-%g)/4,0,1)\"},", threshold, threshold);
    else
        printf("\"tf_params\":{\"kind\":\"ramp\",\"threshold\":%g,\"ramp_end\":%g,"
               "\"ramp_top\":%g,\"opacity\":\"%g*clamp((d-%g)/(%g-%g),0,1)\"},",
               threshold, ramp_end, ramp_top, ramp_top, threshold, ramp_end, threshold);
    printf("\"min_voxel_opacity\":%g,\"max_ray_opacity\":%g,", min_opacity,
           max_ray_opacity);
    printf("\"view\":{\"projection\":\"orthographic\",\"axis\":\"y\",\"step_deg\":%g,"
           "\"fit\":\"%s\",\"window_half\":%.6f,\"px_per_voxel\":%.6f,"
           "\"warmup\":%d},", step_deg, fit, half, px_per_voxel, warmup);
    printf("\"shading\":{\"model\":\"blinn-phong\",\"light_dir_eye\":[0,0,1],"
           "\"ambient\":%g,\"diffuse\":%g,\"specular\":%g,\"shininess\":%g,"
           "\"depth_cue\":false},", MAT_AMBIENT, MAT_DIFFUSE, MAT_SPECULAR,
           MAT_SHININESS);
    printf("\"threads\":1,\"images_written\":%d", nimg);
    if (views_path) {
        printf(",\"zoom\":%.9g,\"views\":[", zoom);
        for (int vi = 0; vi < nviews; vi++) {
            double *t = malloc(sizeof(double) * reps);
            if (!t) die("out of memory%s", "");
            memcpy(t, &render_ms[vi * reps], sizeof(double) * reps);
            qsort(t, reps, sizeof(double), cmp_double);
            printf("%s{\"name\":\"%s\",\"frame_ms_median\":%.4f,\"frame_ms_min\":%.4f,\"reps\":%d}",
                   vi ? "," : "", views[vi].name, median_sorted(t, reps), t[0], reps);
            free(t);
        }
        printf("]");
    }
    if (print_times) {
        printf(",\"frame_ms\":[");
        for (i = 0; i < frames; i++)
            printf("%s%.4f", i ? "," : "", render_ms[i]);
        printf("]");
    }
    printf("}\n");

    vpDestroyContext(vpc);
    free(scalars);
    free(image);
    free(render_ms);
    free(shade_ms);
    free(save);
    free(sorted);
    free(ssorted);
    return 0;
}
