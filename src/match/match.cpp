// PPF matching (docs/matching.md): Drost et al. 2010 voting over all faces in the world frame,
// with what later work found to help (Vidal et al. 2018: normals from a clean neighbourhood and
// non-smooth points left out, pose clustering with averaging, verification of several
// hypotheses by fit) and, for axisymmetric parts, meridian references and spin-free clustering.
#include "hotgauge/match/match.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <memory>
#include <numbers>
#include <optional>

#include "hotgauge/core/parallel.hpp"
#include "internal.hpp"

namespace hotgauge::match {
namespace {

// Tuning (docs/matching.md gives the figures and what they are for).
// Fewer voting samples than this hold no part worth voting for: an empty scene or a fragment.
constexpr std::size_t kMinSceneSamples = 20;
// A plane this much larger than the part's largest extent cannot be one of its faces.
constexpr double kBackgroundExtentPerPart = 1.2;
// A cell with fewer votes than this is a few stray pairs, not a pose.
constexpr std::uint32_t kMinCellVotes = 3;
// A reference point's second-best cell is kept at this share of the best's votes: the flipped
// part seen from one side scores close to the upright one, and verification tells them apart.
constexpr double kSecondCellShare = 0.8;
// Candidates cluster within this many sampling distances (when cluster_distance_mm is 0): about
// the spread of the votes for one pose, whose samples lie a sampling distance apart.
constexpr double kClusterDistancePerSampling = 2.0;
// Verification's coarse ICP only ranks hypotheses: gates from 3 sampling distances (a cluster's
// pose is within about 2) down to half of one, few iterations and a 10 µm stop keep it cheap.
constexpr std::array<double, 3> kCoarseGatesPerSampling = {3.0, 1.5, 0.5};
constexpr int kCoarseIterationsPerStage = 4;
constexpr int kCoarseMaxIterations = 12;
constexpr double kCoarseStopMm = 0.01;
// A scene sample supports a hypothesis within half a sampling distance of its surface (and of
// its region): tighter than the samples' spacing, looser than the coarse fit's error.
constexpr double kVerifyBandPerSampling = 0.5;
// The fine ICP's gates after the first (one sampling distance, where the coarse fit leaves the
// part): 1 mm, then 0.5 mm once the fit is that close (docs/matching.md: 5, 1, 0.5 mm).
constexpr double kFineSecondGateMm = 1.0;
constexpr double kFineLastGateMm = 0.5;
// Iterations per gate of the fine ICP (within icp_max_iterations in all).
constexpr int kFineIterationsPerStage = 10;

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

struct Candidate {
    Eigen::Isometry3d T;
    double votes;
};

struct Cluster {
    Eigen::Isometry3d T;  // of the best member
    double votes = 0;
    Eigen::Vector3d axis_sum = Eigen::Vector3d::Zero(), origin_sum = Eigen::Vector3d::Zero();
    Eigen::Quaterniond q_sum = Eigen::Quaterniond(0, 0, 0, 0);
};

Eigen::Isometry3d from_ref_frames(const Eigen::Matrix<float, 3, 4>& Ts,
                                  const Eigen::Matrix<float, 3, 4>& Tm, float alpha) {
    Eigen::Isometry3d S = Eigen::Isometry3d::Identity(), M = Eigen::Isometry3d::Identity();
    S.matrix().topRows<3>() = Ts.cast<double>();
    M.matrix().topRows<3>() = Tm.cast<double>();
    return S.inverse() * Eigen::AngleAxisd(alpha, Eigen::Vector3d::UnitX()) * M;
}

// Every stride-th scene sample is a reference point: at most max_refs, evenly spread.
std::size_t reference_stride(std::size_t n, int max_refs) {
    const auto m = static_cast<std::size_t>(std::max(1, max_refs));
    return std::max<std::size_t>(1, (n + m - 1) / m);
}

// The model's side of the voting, the same for every scene reference point.
struct VoteTable {
    int A = 0;                                      // α bins over [−π, π)
    float bin = 0, inv_bin = 0;                     // α bin width (rad) and its inverse
    float max_d2 = 0;                               // pairs up to the model's diameter, mm²
    std::size_t row = 0;                            // accumulator cells per model reference
    std::vector<std::uint32_t> cell;                // per table entry: its cell, A + α_m
    std::vector<Eigen::Matrix<float, 3, 4>> T_ref;  // per model reference: to_ref_frame
};

VoteTable vote_table(const Model& model) {
    VoteTable t;
    t.A = model.config.alpha_bins;
    t.bin = 2.0f * std::numbers::pi_v<float> / static_cast<float>(t.A);
    t.inv_bin = 1.0f / t.bin;
    t.max_d2 = static_cast<float>(model.diameter_mm * model.diameter_mm);
    // Accumulator rows of 2A cells per model reference: a vote for α = α_m − α_s lands in cell
    // A + α_m − α_s (never wraps), and cells b and b + A are folded afterwards. Each entry's cell
    // A + α_m is precomputed, so the inner loop is one load, one add, one increment.
    t.row = 2 * static_cast<std::size_t>(t.A);
    t.cell.resize(model.entries.size());
    for (std::size_t e = 0; e < t.cell.size(); ++e) {
        const int am = std::clamp(
            static_cast<int>((model.entries[e].alpha + std::numbers::pi_v<float>)*t.inv_bin), 0,
            t.A - 1);
        t.cell[e] = static_cast<std::uint32_t>(model.entries[e].ref * t.row +
                                               static_cast<std::size_t>(t.A + am));
    }
    t.T_ref.resize(model.refs.size());
    for (std::size_t r = 0; r < model.refs.size(); ++r)
        t.T_ref[r] = to_ref_frame(model.points[model.refs[r]], model.normals[model.refs[r]]);
    return t;
}

// The votes of scene reference point s (frame Ts) into acc: every scene point within the model's
// diameter pairs with it, and each table entry under the pair's key votes for (model reference,
// α_m − α_s) (Drost et al. 2010, the α trick).
void accumulate(const Model& model, const VoteTable& t, const detail::Samples& scene, std::size_t s,
                const Eigen::Matrix<float, 3, 4>& Ts, std::vector<std::uint32_t>& acc) {
    const Eigen::Vector3f& ps = scene.points[s];
    const Eigen::Vector3f& ns = scene.normals[s];
    for (std::size_t j = 0; j < scene.points.size(); ++j) {
        if (j == s || (scene.points[j] - ps).squaredNorm() > t.max_d2) continue;
        const std::uint32_t key = model.key(ps, ns, scene.points[j], scene.normals[j]);
        if (key == kNoKey) continue;
        const std::uint32_t e0 = model.key_begin[key], e1 = model.key_begin[key + 1];
        if (e0 == e1) continue;
        const Eigen::Vector3f q = Ts * scene.points[j].homogeneous();
        const int as = std::clamp(
            static_cast<int>((std::atan2(-q.z(), q.y()) + std::numbers::pi_v<float>)*t.inv_bin), 0,
            t.A - 1);
        const auto off = static_cast<std::uint32_t>(as);  // < A <= every cell's offset
        std::uint32_t* a = acc.data();
        for (std::uint32_t e = e0; e < e1; ++e) ++a[t.cell[e] - off];
    }
}

// Cells b and b + A of a row hold the same α (see VoteTable): their sum, A cells per row.
void fold(const VoteTable& t, std::size_t n_model_refs, const std::vector<std::uint32_t>& acc,
          std::vector<std::uint32_t>& folded) {
    const auto A = static_cast<std::size_t>(t.A);
    for (std::size_t r = 0; r < n_model_refs; ++r)
        for (std::size_t b = 0; b < A; ++b)
            folded[r * A + b] = acc[r * t.row + b] + acc[r * t.row + b + A];
}

// The pose candidates of one scene reference point (frame Ts): its best cell, and a second one
// when nearly as good (the flipped part seen from one side scores close).
std::vector<Candidate> peak_candidates(const VoteTable& t, const std::vector<std::uint32_t>& folded,
                                       const Eigen::Matrix<float, 3, 4>& Ts) {
    std::size_t best = 0, second = 0;
    for (std::size_t c = 1; c < folded.size(); ++c)
        if (folded[c] > folded[best]) best = c;
    for (std::size_t c = 0; c < folded.size(); ++c)
        if (c != best && folded[c] > folded[second]) second = c;
    std::vector<Candidate> found;
    for (std::size_t c : {best, second}) {
        if (folded[c] < kMinCellVotes ||
            (c == second && (second == best || folded[c] < folded[best] * kSecondCellShare)))
            continue;
        const auto r = c / static_cast<std::size_t>(t.A);
        const float alpha = static_cast<float>(c % static_cast<std::size_t>(t.A)) * t.bin;
        found.push_back({from_ref_frames(Ts, t.T_ref[r], alpha), static_cast<double>(folded[c])});
    }
    return found;
}

// Hough voting: per scene reference point, an accumulator over (model reference × α).
std::vector<Candidate> vote(const Model& model, const detail::Samples& scene, int max_refs,
                            int threads) {
    const VoteTable table = vote_table(model);
    const auto n = scene.points.size();
    const std::size_t stride = reference_stride(n, max_refs);
    // Scene reference points vote independently: they are spread over the cores, each worker
    // with its own accumulator, and each reference's candidates are kept apart and concatenated
    // in reference order, so the result is the same as from one thread.
    const std::size_t n_refs = (n + stride - 1) / stride;
    std::vector<std::vector<Candidate>> found(n_refs);
    struct Scratch {
        std::vector<std::uint32_t> acc, folded;
    };
    std::vector<Scratch> scratch(core::worker_count(threads));
    core::parallel_for(n_refs, threads, [&](std::size_t ref, unsigned worker) {
        auto& acc = scratch[worker].acc;
        auto& folded = scratch[worker].folded;
        acc.assign(model.refs.size() * table.row, 0);
        folded.resize(model.refs.size() * static_cast<std::size_t>(table.A));
        const std::size_t s = ref * stride;
        const auto Ts = to_ref_frame(scene.points[s], scene.normals[s]);
        accumulate(model, table, scene, s, Ts, acc);
        fold(table, model.refs.size(), acc, folded);
        found[ref] = peak_candidates(table, folded, Ts);
    });
    std::vector<Candidate> out;
    for (auto& f : found) out.insert(out.end(), f.begin(), f.end());
    return out;
}

std::vector<Cluster> cluster(const Model& model, std::vector<Candidate> cands, double angle_deg,
                             double dist_mm) {
    std::sort(cands.begin(), cands.end(),
              [](const Candidate& a, const Candidate& b) { return a.votes > b.votes; });
    const double cos_max = std::cos(angle_deg * std::numbers::pi / 180.0);
    std::vector<Cluster> clusters;
    for (const auto& c : cands) {
        const Eigen::Vector3d axis = c.T.linear().col(2), origin = c.T.translation();
        const Eigen::Quaterniond q(c.T.linear());
        Cluster* home = nullptr;
        for (auto& k : clusters) {
            if ((k.T.translation() - origin).norm() > dist_mm) continue;
            const bool close = model.axisymmetric
                                   ? k.T.linear().col(2).dot(axis) > cos_max
                                   : std::abs(Eigen::Quaterniond(k.T.linear()).dot(q)) >
                                         std::cos(0.5 * angle_deg * std::numbers::pi / 180.0);
            if (close) {
                home = &k;
                break;
            }
        }
        if (!home) {
            clusters.push_back({c.T});
            home = &clusters.back();
        }
        home->votes += c.votes;
        home->axis_sum += c.votes * axis;
        home->origin_sum += c.votes * origin;
        const Eigen::Quaterniond q0(home->T.linear());
        const double sgn = q0.dot(q) < 0 ? -1.0 : 1.0;
        home->q_sum.coeffs() += sgn * c.votes * q.coeffs();
    }
    // Each cluster's pose: the vote-weighted mean of its members.
    for (auto& k : clusters) {
        k.T.translation() = k.origin_sum / k.votes;
        if (model.axisymmetric) {
            const Eigen::Vector3d a = k.axis_sum.normalized();
            k.T.linear() =
                Eigen::Quaterniond::FromTwoVectors(k.T.linear().col(2), a).toRotationMatrix() *
                k.T.linear();
        } else {
            k.T.linear() = k.q_sum.normalized().toRotationMatrix();
        }
    }
    std::sort(clusters.begin(), clusters.end(),
              [](const Cluster& a, const Cluster& b) { return a.votes > b.votes; });
    return clusters;
}

// What the matcher works on: the scene in the world frame and the model surface ICP fits.
struct Prepared {
    detail::Samples scene;                           // oriented voting samples
    std::vector<Eigen::Vector3f> dense;              // the dense ICP grid
    std::shared_ptr<const detail::Surface> surface;  // the model's (kept with it)
    std::int64_t background_removed = 0;             // voting samples on the background plane
};

// Drops the background plane (the support plate, a wall) from the voting samples and the grid,
// when there is one; returns how many voting samples it took.
std::int64_t remove_background_plane(const Model& model, const detail::Surface& surface,
                                     double band_mm, detail::Samples& scene,
                                     std::vector<Eigen::Vector3f>& dense) {
    const double part_extent = 2.0 * surface.half_size();
    // Larger than any plane of the part: for an axisymmetric part its largest diameter.
    const double min_extent =
        kBackgroundExtentPerPart * (model.axisymmetric ? 2.0 * surface.max_radius() : part_extent);
    const auto pl = detail::background_plane(scene, band_mm, min_extent);
    if (!pl) return 0;
    const auto band = static_cast<float>(band_mm);
    detail::Samples kept;
    for (std::size_t i = 0; i < scene.points.size(); ++i)
        if (std::abs(pl->distance(scene.points[i])) >= band) {
            kept.points.push_back(scene.points[i]);
            kept.normals.push_back(scene.normals[i]);
        }
    const auto removed = static_cast<std::int64_t>(scene.points.size() - kept.points.size());
    scene = std::move(kept);
    std::erase_if(dense,
                  [&](const Eigen::Vector3f& p) { return std::abs(pl->distance(p)) < band; });
    return removed;
}

// Step 1, prepare (docs/matching.md, "Scene"): the voting samples with their normals, the dense
// ICP grid and the model surface, then the background plane taken out of both scene sets.
Prepared prepare(const Model& model, const core::Recording& rec, const core::FaceDisplacements& u,
                 const MatchConfig& cfg, double sampling) {
    Prepared p;
    // Independent, so built concurrently (the samples take the longest; the other worker does
    // the rest).
    core::parallel_for(3, cfg.threads, [&](std::size_t job, unsigned) {
        if (job == 0)
            p.scene = detail::voting_samples(rec, u, sampling, cfg.normal_radius_mm);
        else if (job == 1)
            p.dense = detail::grid_points(rec, u, cfg.icp_grid_mm);
        else
            p.surface = model.surface.get(model);
    });
    if (cfg.remove_background_plane)
        p.background_removed =
            remove_background_plane(model, *p.surface, cfg.background_band_mm, p.scene, p.dense);
    return p;
}

struct Votes {
    std::vector<Cluster> clusters;  // most votes first
    std::int64_t reference_points = 0;
};

// Step 2, vote and cluster (Drost et al. 2010; Vidal et al. 2018): Hough voting from evenly
// spread scene reference points, then the pose candidates clustered greedily in vote order.
Votes vote_and_cluster(const Model& model, const detail::Samples& scene, const MatchConfig& cfg,
                       double sampling) {
    Votes out;
    auto cands = vote(model, scene, cfg.max_reference_points, cfg.threads);
    const std::size_t stride = reference_stride(scene.points.size(), cfg.max_reference_points);
    out.reference_points = static_cast<std::int64_t>((scene.points.size() + stride - 1) / stride);
    const double dist = cfg.cluster_distance_mm > 0 ? cfg.cluster_distance_mm
                                                    : kClusterDistancePerSampling * sampling;
    out.clusters = cluster(model, std::move(cands), cfg.cluster_angle_deg, dist);
    return out;
}

struct Verified {
    detail::IcpResult icp;  // the winner's coarse fit
    double votes = 0;       // its cluster's votes
    int hypotheses = 0;     // clusters verified
};

// Step 3, verify (Vidal et al. 2018): coarse ICP of the best clusters on the voting samples; the
// one the most scene samples support wins (the flipped hub seen from one side loses here).
Verified verify(const Model& model, const detail::Surface& surface, const detail::Samples& scene,
                const std::vector<Cluster>& clusters, const MatchConfig& cfg, double sampling) {
    const double scale0 = cfg.scale.value_or(1.0);
    detail::IcpOptions coarse;
    coarse.gates_mm = {kCoarseGatesPerSampling[0] * sampling, kCoarseGatesPerSampling[1] * sampling,
                       kCoarseGatesPerSampling[2] * sampling};
    coarse.iterations_per_stage = kCoarseIterationsPerStage;
    coarse.max_iterations = kCoarseMaxIterations;
    coarse.stop_mm = kCoarseStopMm;
    struct Hyp {
        detail::IcpResult icp;
        detail::Support sup;
        double votes;
    };
    std::optional<Hyp> best;
    const int n_hyp = std::min<int>(cfg.max_hypotheses, static_cast<int>(clusters.size()));
    for (int h = 0; h < n_hyp; ++h) {
        auto r = detail::icp(surface, model, scene.points, clusters[h].T, scale0, coarse);
        const auto sup =
            detail::support(surface, scene.points, r.T_world_part, r.scale,
                            kVerifyBandPerSampling * sampling, kVerifyBandPerSampling * sampling);
        if (!best || sup.inliers > best->sup.inliers) best = Hyp{r, sup, clusters[h].votes};
    }
    return {best->icp, best->votes, n_hyp};
}

// Step 4, refine: fine ICP on the dense grid near the part, walls free and the scale estimated
// when not given (docs/matching.md, "ICP", "Scale"). `dense` keeps only the points near the part.
detail::IcpResult refine(const Model& model, const detail::Surface& surface,
                         const detail::IcpResult& coarse, const MatchConfig& cfg, double sampling,
                         std::vector<Eigen::Vector3f>& dense) {
    {
        const Eigen::Isometry3f T_pw = coarse.T_world_part.inverse().cast<float>();
        const auto s = static_cast<float>(coarse.scale);
        std::erase_if(dense, [&](const Eigen::Vector3f& p) {
            return !surface.inside_region(T_pw * p, s, static_cast<float>(sampling));
        });
    }
    detail::IcpOptions fine;
    fine.gates_mm = {sampling, kFineSecondGateMm, kFineLastGateMm};
    fine.iterations_per_stage = kFineIterationsPerStage;
    fine.max_iterations = cfg.icp_max_iterations;
    fine.stop_mm = cfg.icp_stop_mm;
    fine.estimate_scale = !cfg.scale.has_value();
    fine.free_radii = true;
    return detail::icp(surface, model, dense, coarse.T_world_part, coarse.scale, fine);
}

// Step 5, the verdict (docs/matching.md, "Verdict"): the fit's support on the dense points near
// the part; found when enough of them lie on the surface.
void verdict(const Model& model, const detail::Surface& surface,
             const std::vector<Eigen::Vector3f>& dense, const detail::IcpResult& fin,
             const MatchConfig& cfg, MatchResult& res) {
    const double band = cfg.score_band_mm > 0 ? cfg.score_band_mm : cfg.inlier_band_mm;
    const auto sup = detail::support(surface, dense, fin.T_world_part, fin.scale, band, band);
    res.T_world_part = model.axisymmetric ? canonical_spin(fin.T_world_part) : fin.T_world_part;
    res.scale = fin.scale;
    res.scale_estimated = !cfg.scale.has_value();
    res.rms_mm = fin.rms_mm;
    res.iterations = fin.iterations;
    res.inliers = sup.inliers;
    res.score = sup.fraction();
    if (sup.inliers < cfg.min_inliers) {
        res.reason = "part not found: best score " + std::to_string(res.score) + " with " +
                     std::to_string(sup.inliers) + " supporting points (need " +
                     std::to_string(cfg.min_inliers) + ")";
        return;
    }
    if (res.score < cfg.min_score) {
        res.reason = "part not found: best score " + std::to_string(res.score) + " < " +
                     std::to_string(cfg.min_score);
        return;
    }
    res.found = true;
}

}  // namespace

Eigen::Isometry3d canonical_spin(const Eigen::Isometry3d& T) {
    const Eigen::Vector3d a = T.linear().col(2);
    Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
    if (a.z() < -1.0 + 1e-12)
        out.linear() =
            Eigen::AngleAxisd(std::numbers::pi, Eigen::Vector3d::UnitX()).toRotationMatrix();
    else
        out.linear() =
            Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), a).toRotationMatrix();
    out.translation() = T.translation();
    return out;
}

AxisError axis_error(const Eigen::Isometry3d& T_true, const Eigen::Isometry3d& T_est) {
    const Eigen::Vector3d a_t = T_true.linear().col(2), a_e = T_est.linear().col(2);
    AxisError e;
    e.angle_deg = std::atan2(a_t.cross(a_e).norm(), a_t.dot(a_e)) * 180.0 / std::numbers::pi;
    const Eigen::Vector3d d = T_true.translation() - T_est.translation();
    e.axial_mm = d.dot(a_e);
    e.radial_mm = (d - e.axial_mm * a_e).norm();
    e.axial_mm = std::abs(e.axial_mm);
    return e;
}

MatchResult match(const Model& model, const core::Recording& rec, const core::FaceDisplacements& u,
                  const MatchConfig& cfg) {
    MatchResult res;
    const auto t0 = Clock::now();
    const double sampling =
        cfg.scene_sampling_mm > 0 ? cfg.scene_sampling_mm : model.config.sampling_mm;
    // 1. Prepare: voting samples with normals, the dense ICP grid and the model surface, the
    //    background plane removed.
    Prepared prep = prepare(model, rec, u, cfg, sampling);
    const detail::Surface& surface = *prep.surface;
    res.background_removed = prep.background_removed;
    res.scene_points = static_cast<std::int64_t>(prep.scene.points.size());
    res.stage_ms.emplace_back("prepare", ms_since(t0));
    if (prep.scene.points.size() < kMinSceneSamples) {
        res.reason = "part not found: " + std::to_string(prep.scene.points.size()) +
                     " usable scene samples (empty or tiny scene)";
        return res;
    }
    // 2. Vote and cluster: pose hypotheses, most votes first.
    const auto t1 = Clock::now();
    const Votes votes = vote_and_cluster(model, prep.scene, cfg, sampling);
    res.reference_points = votes.reference_points;
    res.stage_ms.emplace_back("vote", ms_since(t1));
    if (votes.clusters.empty()) {
        res.reason = "part not found: no pose received votes";
        return res;
    }
    // 3. Verify: the best hypotheses by a coarse fit to the voting samples.
    const auto t2 = Clock::now();
    const Verified best = verify(model, surface, prep.scene, votes.clusters, cfg, sampling);
    res.hypotheses = best.hypotheses;
    res.votes = best.votes;
    res.stage_ms.emplace_back("verify", ms_since(t2));
    // 4. Refine: the winner by a fine fit to the dense grid near it.
    const auto t3 = Clock::now();
    const detail::IcpResult fin = refine(model, surface, best.icp, cfg, sampling, prep.dense);
    res.stage_ms.emplace_back("icp", ms_since(t3));
    // 5. Verdict: found when enough of the dense points lie on the fitted surface.
    verdict(model, surface, prep.dense, fin, cfg, res);
    return res;
}

}  // namespace hotgauge::match
